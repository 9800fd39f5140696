#include "pipeline/process.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <system_error>

#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/system_stats.h"
#include "pipeline/height_reliability.h"
#include "pipeline/held_out_lights.h"
#include "pipeline/material_writer.h"
#include "pipeline/side_run.h"
#include "pipeline/supersampled_reconstruction.h"
#include "pipeline/stages.h"
#include "u3m/image_io.h"
#include "u3m/material.h"
#include "u3m/material_json.h"
#include "u3mscan/version.h"

namespace u3mscan {
namespace fs = std::filesystem;

namespace {

// The U3M key of each fitted parameter (fitting::FitParameter order).
constexpr const char* kU3mKeyOfFitParameter[fitting::kFitParameterCount] = {
    "roughness", "specular_value", "specular_tint", "sheen_value", "sheen_tint", "anisotropy_value", "metalness"};


// Texture factor of the anisotropy rotation (degrees): the stretch repeats every half turn, so a
// texture of rotation / 180 in 0..1 with factor 180 holds every turn the fit finds.
constexpr double kRotationTextureFactorDeg = 180.0;

// The writer's choice for one fitted map from the fit's decision: the U3M default when not
// measured, a constant when uniform (or without an image), else the texture `map`, written as
// map / texture_factor with that factor. A decision without a reason gets the default wording.
ScalarMapChoice ChoiceFromDecision(const char* u3m_key, const fitting::MapReport& decision, const Image& map,
                                   double pitch_mm, const char* texture_reason, double texture_factor = 1.0) {
  ScalarMapChoice choice;
  choice.u3m_key = u3m_key;
  choice.value = decision.value;
  choice.reason = decision.reason;
  if (decision.measured && !decision.reliable) choice.unreliable_reason = decision.unreliable_reason;
  if (!decision.measured) {
    choice.source = ParameterSource::kDefault;
    if (choice.reason.empty()) choice.reason = "not constrained by this capture";
  } else if (decision.constant || map.empty()) {
    choice.source = ParameterSource::kConstant;
    if (choice.reason.empty()) choice.reason = "uniform within noise";
  } else {
    choice.source = ParameterSource::kMeasured;
    if (choice.reason.empty()) choice.reason = texture_reason;
    choice.map = map;
    if (texture_factor != 1.0) {
      for (float& v : choice.map.data()) v = static_cast<float>(v / texture_factor);
    }
    choice.map.set_pitch_mm(pitch_mm);
    choice.texture_factor = texture_factor;
  }
  return choice;
}

// --created: the u3m reader's RFC 3339 parser, restricted to UTC written with 'Z' (the form the
// conventions ask writers for), so a material never gets a time the operator did not mean.
std::optional<std::int64_t> ParseUtcTimestamp(const std::string& text) {
  const std::optional<ParsedTimestamp> parsed = ParseTimestamp(text);
  if (!parsed || !parsed->has_zone || parsed->has_offset || parsed->space_separator) return std::nullopt;
  return parsed->utc_ms;
}

nlohmann::json Vector3Json(const Eigen::Vector3d& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }

// Our custom section: everything about how the material was made that a U3M has no field for.
// Run times are NOT in it (they go to the report), so two runs write the same material.
nlohmann::json CustomSection(const PreparedCapture& prepared, const ProcessOptions& options,
                             const std::vector<ParameterRecord>& parameters, const nlohmann::json& quality) {
  const Manifest& manifest = prepared.capture.manifest();
  nlohmann::json custom;
  custom["scanner"] = {{"vendor", manifest.scanner.vendor},
                       {"model", manifest.scanner.model},
                       {"serial", manifest.scanner.serial},
                       {"software", manifest.scanner.software}};
  nlohmann::json capture_info = {{"format", manifest.format}, {"sample", manifest.sample.name}};
  for (const char* key : {"capture_time", "captured", "created"}) {
    if (manifest.extra.contains(key)) capture_info["capture_time"] = manifest.extra[key];
  }
  custom["capture"] = capture_info;
  custom["software"] = {{"name", kSoftwareName}, {"version", kSoftwareVersion}};
  custom["processing"] = {{"preset", PresetName(options.preset)},
                          {"schema", options.schema},
                          {"solver", options.solver.empty() ? "preset" : options.solver},
                          {"integrator", options.integrator.empty() ? "preset" : options.integrator},
                          {"fit_mode", options.fit_mode.empty() ? "preset" : options.fit_mode},
                          {"levelling", options.levelling},
                          {"level_normals", options.level_normals},
                          {"dpi", prepared.calibration.grid.dpi()},
                          {"surface_z_mm", prepared.calibration.surface_z_mm}};
  nlohmann::json cameras = nlohmann::json::array();
  for (const auto& camera : prepared.calibration.cameras) {
    nlohmann::json c = {{"id", camera.id}, {"intrinsics_source", camera.intrinsics_source}, {"pose_source", camera.pose_source}};
    if (camera.reprojection_error_px) c["reprojection_error_px"] = *camera.reprojection_error_px;
    cameras.push_back(c);
  }
  nlohmann::json lights = nlohmann::json::array();
  for (const auto& light : prepared.calibration.lights) {
    nlohmann::json l = {{"id", light.model.id},
                        {"type", light.model.type == LightType::kPoint ? "point" : "directional"},
                        {"source", light.source},
                        {"intensity_rgb", Vector3Json(light.model.intensity_rgb)}};
    if (light.model.type == LightType::kPoint) l["position_mm"] = Vector3Json(light.model.position_in_world_mm);
    else l["direction"] = Vector3Json(light.model.direction_in_world);
    if (light.residual) l["residual"] = {{"value", *light.residual}, {"unit", light.residual_unit}};
    lights.push_back(l);
  }
  custom["geometry"] = {{"cameras", cameras}, {"lights", lights}};
  nlohmann::json exposures = nlohmann::json::array();
  for (const FrameSpec& frame : manifest.frames) {
    if (frame.role == FrameRole::kSample) {
      exposures.push_back({{"file", frame.file}, {"light", frame.light.value_or("")}, {"exposure_s", frame.exposure_s}});
    }
  }
  custom["exposures"] = exposures;
  custom["calibration"] = prepared.calibration.ToJson();
  nlohmann::json sources = nlohmann::json::object();
  for (const auto& p : parameters) {
    sources[p.name] = {{"source", ParameterSourceName(p.source)}, {"reason", p.reason}, {"reliable", p.reliable()}};
    if (!p.reliable()) sources[p.name]["unreliable_reason"] = p.unreliable_reason;
  }
  custom["parameter_sources"] = sources;
  custom["quality"] = quality;
  return custom;
}

void WriteDebugMap(const Image& image, const fs::path& path) {
  if (image.empty()) return;
  ImageWriteOptions write;
  write.format = SampleFormat::kFloat32;
  WriteImageFile(image, path, write);
}

}  // namespace

bool ProcessOptions::Check(std::string* why) const {
  auto fail = [&](const std::string& message) {
    if (why) *why = message;
    return false;
  };
  if (schema != "auto" && schema != "1.0" && schema != "1.1") return fail("--schema must be auto, 1.0 or 1.1");
  if (dpi && !(*dpi > 0.0 && *dpi <= 10000.0)) return fail("--dpi must be a number in (0, 10000]");
  if (id && !IsUuid4(*id)) return fail("--id must be a version-4 UUID such as 3f2c1a9e-8b7d-4c6e-9a5f-0123456789ab");
  if (created && !ParseUtcTimestamp(*created)) return fail("--created must be a UTC time like 2026-11-22T10:00:00Z");
  if (!solver.empty() && solver != "ls" && solver != "robust") return fail("--solver must be ls or robust");
  if (!(max_memory_gib > 0.0 && max_memory_gib <= 1e6)) return fail("--max-memory must be a number of GiB in (0, 1e6]");
  if (ps_supersample < 0 || ps_supersample > kMaxPsSupersample) {
    return fail("--ps-supersample must be 0 (as fine as the camera resolves) or 1 to " + std::to_string(kMaxPsSupersample));
  }
  if (!integrator.empty() && integrator != "dct" && integrator != "robust") return fail("--integrator must be dct or robust");
  if (levelling != "none" && levelling != "plane" && levelling != "quadratic") {
    return fail("--level must be none, plane or quadratic");
  }
  if (!fit_mode.empty() && fit_mode != "clusters" && fit_mode != "per-pixel") return fail("--fit-mode must be clusters or per-pixel");
  for (std::size_t i = 0; i < hold_out_lights.size(); ++i) {
    if (hold_out_lights[i].empty()) return fail("--hold-out-lights must list light ids such as L03,L09");
    for (std::size_t j = 0; j < i; ++j) {
      if (hold_out_lights[j] == hold_out_lights[i]) return fail("--hold-out-lights names " + hold_out_lights[i] + " twice");
    }
  }
  return true;
}


fs::path MaterialPathFor(const CaptureJob& job, const ProcessOptions& options) {
  return job.out_dir / (job.name + (options.package ? ".u3ma" : ".u3m"));
}

bool IsOutputComplete(const CaptureJob& job, const ProcessOptions& options) {
  std::error_code ec;
  if (!fs::is_regular_file(MaterialPathFor(job, options), ec)) return false;
  std::ifstream in(job.out_dir / "report.json");
  if (!in) return false;
  try {
    const nlohmann::json report = nlohmann::json::parse(in);
    return report.value("status", "") == "ok";
  } catch (const std::exception&) {
    return false;
  }
}

ProcessResult ProcessCapture(const CaptureJob& job, const ProcessOptions& options, const ProgressCallback& progress) {
  std::string why;
  if (!options.Check(&why)) throw InputError("command line", "", why);
  const double run_start = SteadySeconds();
  ProcessResult result;
  RunReport& report = result.report;
  report.capture_name = job.name;
  report.capture_path = job.capture_dir.string();
  report.output_path = job.out_dir.string();
  report.started_utc = FormatUtcTimestamp(NowUtcMs());
  report.preset = PresetName(options.preset);

  StageOptions stages = OptionsForPreset(options.preset);
  SetDecodeCacheBudget(options.max_memory_gib, &stages);
  if (options.dpi) stages.calibration.dpi = options.dpi;
  if (!options.solver.empty()) stages.photometric_stereo.solver = reconstruction::ParsePsSolver(options.solver);
  if (!options.integrator.empty()) {
    stages.integration.method = reconstruction::ParseIntegrator(options.integrator);
    stages.photometric_stereo.integration.method = stages.integration.method;
  }
  if (!options.fit_mode.empty()) stages.fit.mode = fitting::ParseFitMode(options.fit_mode);
  stages.mark_cast_shadows = !options.no_cast_shadows;
  stages.fit_clusters_on_fine_grid = !options.fit_on_maps_grid;
  stages.base_colour_from_fine_grid = !options.fit_on_maps_grid;
  stages.place_fine_pixels_on_plan = !options.no_plan_placement;
  stages.fit_facets = !options.one_normal_per_pixel;
  stages.refine_top_view_normals = !options.no_top_view_refinement;
  stages.follow_fibres = stages.follow_fibres || options.follow_fibres;
  if (options.one_pixel_prior) stages.fit.pixel_prior_from_samples = false;
  if (options.normal_then_lobe) stages.fit.refine_normal_with_lobe = false;
  report.options = {{"cast_shadows", stages.mark_cast_shadows}, {"preset", report.preset}, {"schema", options.schema}, {"package", options.package},
                    {"fit_mode", fitting::FitModeName(stages.fit.mode)},
                    {"debug_maps", options.debug_maps},
                    {"solver", reconstruction::PsSolverName(stages.photometric_stereo.solver)},
                    {"integrator", reconstruction::IntegratorName(stages.integration.method)},
                    {"max_memory_gib", options.max_memory_gib},
                    {"ps_supersample", options.ps_supersample},
                    {"levelling", options.levelling},
                    {"level_normals", options.level_normals},
                    {"fit_clusters_on_fine_grid", stages.fit_clusters_on_fine_grid},
                    {"base_colour_from_fine_grid", stages.base_colour_from_fine_grid},
                    {"plan_placement", stages.place_fine_pixels_on_plan},
                    {"fit_facets", stages.fit_facets},
                    {"top_view_refinement", stages.refine_top_view_normals},
                    {"follow_fibres", stages.follow_fibres},
                    {"pixel_prior_from_samples", stages.fit.pixel_prior_from_samples},
                    {"refine_normal_with_lobe", stages.fit.refine_normal_with_lobe},
                    {"hold_out_lights", options.hold_out_lights}};
  if (options.dpi) report.options["dpi"] = *options.dpi;

  PreparedCapture prepared = PrepareCapture(job.capture_dir, stages, &report, progress);
  const Manifest& manifest = prepared.capture.manifest();

  ScanMaterialRequest request;
  request.name = manifest.sample.name.empty() ? job.name : manifest.sample.name;
  request.file_stem = job.name;
  request.description = manifest.sample.description;
  request.id = options.id;
  if (options.created) request.created_ms = ParseUtcTimestamp(*options.created);
  request.schema = options.schema;
  request.package = options.package;
  request.thickness_mm = manifest.sample.thickness_mm;
  request.weight_gsm = manifest.sample.weight_gsm;
  request.vendor_key = manifest.scanner.vendor.empty() ? std::string(kOwnVendorKey) : manifest.scanner.vendor;
  if (!(request.thickness_mm && request.weight_gsm)) {
    const char* reason = request.thickness_mm ? "U3M physics needs the sample's weight too (sample.weight_gsm)"
                         : request.weight_gsm ? "U3M physics needs the sample's thickness too (sample.thickness_mm)"
                                              : "the manifest gives no thickness and weight";
    report.steps.push_back({"physics", false, reason, 0.0});
  }

  struct DebugMaps {
    std::string prefix;
    Image normal, albedo, height, confidence, residual;
    std::vector<std::pair<std::string, Image>> fitted;
  };
  std::vector<DebugMaps> debug;
  nlohmann::json quality = nlohmann::json::object();

  const MetricGrid& grid = prepared.calibration.grid;
  for (const std::string& side : prepared.sides) {
    // Alpha, reconstruction and fit of the side as side_run.h says.
    SideRun run = RunSide(prepared, side, stages,
                          {.max_memory_gib = options.max_memory_gib, .ps_supersample = options.ps_supersample,
                           .hold_out_lights = options.hold_out_lights},
                          &report, progress);
    const Image& alpha = run.alpha;
    const Stack& stack = run.stack;
    const SideReconstruction& reconstruction = run.reconstruction;
    const fitting::FitResult& fit = run.fit;
    const Image& residual = run.residual;
    const std::optional<HeldOutCheck>& held_out_check = run.held_out;

    // The side's maps for the writer.
    SideMaps maps;
    maps.side = side;
    maps.base_color = fit.base_color.empty() ? reconstruction.photometric_stereo.albedo : fit.base_color;
    maps.base_color.set_pitch_mm(grid.pitch_mm);
    maps.normal = reconstruction.photometric_stereo.normal;
    if (run.fitted_normals) maps.normal_source = "photometric stereo, refined with the fitted model (height integrated from these)";
    maps.normal.set_pitch_mm(grid.pitch_mm);
    maps.height_mm = reconstruction.height_mm;
    maps.alpha = alpha;
    // The sample's tilt (or bowl) out of the written height, and its tilt out of the normals when
    // asked (--level-normals); every stage above used the heights as integrated.
    const Image& level_weight = reconstruction.valid.empty() ? alpha : reconstruction.valid;
    report.steps.push_back(LevelSideMaps(reconstruction::ParseLevelling(options.levelling), side, level_weight,
                                         &maps.height_mm, options.level_normals ? &maps.normal : nullptr));
    maps.height_unreliable_reason = HeightUnreliableReason(reconstruction.photometric_stereo);
    for (int p = 0; p < fitting::kFitParameterCount; ++p) {
      maps.scalars.push_back(ChoiceFromDecision(kU3mKeyOfFitParameter[p], fit.maps[p], fit.parameter_maps[p], grid.pitch_mm,
                                                "fitted per pixel: varies more than its noise (texture)"));
    }
    // The rotation of the anisotropic stretch (fitting/shading_frame.h for its sense).
    maps.scalars.push_back(ChoiceFromDecision("anisotropy_rotation", fit.rotation_report, fit.anisotropy_rotation_deg,
                                              grid.pitch_mm, "one turn per cluster (texture)",
                                              kRotationTextureFactorDeg));

    // Quality figures of this side.
    const auto& ps = reconstruction.photometric_stereo;
    double rms = 0.0, weight = 0.0;
    for (const auto& cluster : fit.clusters) {
      rms += cluster.rms_relative_residual * static_cast<double>(cluster.pixel_count);
      weight += static_cast<double>(cluster.pixel_count);
    }
    quality[side] = {{"mean_confidence", ps.confidence.ChannelMean(0)},
                     {"ill_conditioned_pixels", ps.ill_conditioned_pixels},
                     {"dark_pixels", ps.dark_pixels},
                     {"regularised_pixels", ps.regularised_pixels},
                     {"cast_shadow_share", reconstruction.cast_shadow_share},
                     {"fit_rms_relative_residual", weight > 0 ? rms / weight : 0.0},
                     {"mean_relative_render_residual", run.residual_mean},
                     {"fit_converged", fit.convergence.all_converged}};
    if (held_out_check) quality[side]["held_out_lights"] = HeldOutCheckToJson(*held_out_check);

    // Report thumbnails: a few input observations, every map, confidence and residual.
    const std::size_t n = stack.observations.size();
    for (std::size_t k = 0; k < std::min<std::size_t>(n, 4); ++k) {
      const Observation& o = stack.observations[k * n / std::min<std::size_t>(n, 4)];
      report.images.push_back({side + " light " + stack.lights[o.light].id, "input", o.rgb, false});
    }
    report.images.push_back({side + " base colour", "map", maps.base_color, true});
    Image normal_display = maps.normal;
    for (float& v : normal_display.data()) v = 0.5f * (v + 1.0f);
    report.images.push_back({side + " normal", "map", normal_display, true});
    report.images.push_back({side + " height (mm)", "map", maps.height_mm, false});
    if (!alpha.empty()) report.images.push_back({side + " alpha", "map", alpha, false});
    for (const auto& choice : maps.scalars) {
      if (!choice.map.empty()) report.images.push_back({side + " " + choice.u3m_key, "map", choice.map, false});
    }
    report.images.push_back({side + " confidence", "quality", ps.confidence, false});
    report.images.push_back({side + " render residual (relative)", "quality", residual, false});

    if (options.debug_maps) {
      DebugMaps d;
      d.prefix = side == "front" ? "" : side + "_";
      d.normal = maps.normal;  // levelled, as written
      d.albedo = ps.albedo;
      d.height = maps.height_mm;
      d.confidence = ps.confidence;
      d.residual = residual;
      for (int p = 0; p < fitting::kFitParameterCount; ++p) {
        if (!fit.parameter_maps[p].empty()) d.fitted.emplace_back(fitting::FitParameterName(p), fit.parameter_maps[p]);
      }
      if (!fit.base_color.empty()) d.fitted.emplace_back("base_color", fit.base_color);
      if (!fit.anisotropy_rotation_deg.empty()) d.fitted.emplace_back("anisotropy_rotation", fit.anisotropy_rotation_deg);
      debug.push_back(std::move(d));
    }
    request.sides.push_back(std::move(maps));
    prepared.capture.ReleaseCache();
  }

  // The custom section lists every parameter decision (the same ones the writer applies); run
  // times stay out of it so that two runs write the same material.
  const double write_start = SteadySeconds();
  std::vector<ParameterRecord> decided;
  for (const SideMaps& side : request.sides) {
    for (const auto& s : side.scalars) decided.push_back({side.side + "/" + s.u3m_key, s.source, s.reason, s.value, 0.0, s.unreliable_reason});
  }
  request.custom_section = CustomSection(prepared, options, decided, quality);
  const ScanMaterialResult written = WriteScanMaterial(request, job.out_dir, /*overwrite=*/true);
  result.material = written.material_path;
  report.parameters = written.parameters;
  report.quality = quality;
  report.steps.push_back({"write U3M " + std::string(SchemaVersionName(written.version)) + (options.package ? " package" : ""),
                          true, std::to_string(written.files.size()) + " texture files", SteadySeconds() - write_start});

  if (options.debug_maps) {
    const fs::path dir = job.out_dir / "maps";
    fs::create_directories(dir);
    for (const DebugMaps& d : debug) {
      WriteDebugMap(d.normal, dir / (d.prefix + "normal.exr"));
      WriteDebugMap(d.albedo, dir / (d.prefix + "albedo.exr"));
      WriteDebugMap(d.height, dir / (d.prefix + "height.exr"));
      WriteDebugMap(d.confidence, dir / (d.prefix + "confidence.exr"));
      WriteDebugMap(d.residual, dir / (d.prefix + "residual.exr"));
      for (const auto& [name, map] : d.fitted) WriteDebugMap(map, dir / (d.prefix + name + ".exr"));
    }
  }

  report.total_seconds = SteadySeconds() - run_start;
  report.peak_memory_mib = static_cast<double>(PeakResidentBytes()) / (1024.0 * 1024.0);
  WriteReportHtml(report, job.out_dir / "report.html");
  WriteReportJson(report, job.out_dir / "report.json");  // last: marks the output complete
  report.images.clear();  // thumbnails are in the HTML; keep the result light for batches
  return result;
}

}  // namespace u3mscan
