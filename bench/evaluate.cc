#include "bench/evaluate.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "bench/error_stats.h"
#include "bench/truth_footprint.h"
#include "bench/truth_maps.h"
#include "core/colour.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/principled_brdf.h"
#include "datasets_synthetic/renderer.h"
#include "fitting/shading_frame.h"
#include "pipeline/json_number.h"
#include "reconstruction/relief_levelling.h"
#include "u3m/image_io.h"

namespace u3mscan::bench {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRadToDeg = 180.0 / M_PI;
constexpr int kParameterCount = 7;
// fitting::FitParameter order; names of maps/*.exr (fitting::FitParameterName) and U3M keys.
constexpr const char* kParameterNames[kParameterCount] = {"roughness",  "specular",    "specular_tint", "sheen",
                                                          "sheen_tint", "anisotropic", "metallic"};
constexpr const char* kU3mKeys[kParameterCount] = {"roughness",  "specular_value",   "specular_tint", "sheen_value",
                                                   "sheen_tint", "anisotropy_value", "metalness"};
constexpr double kU3mDefaults[kParameterCount] = {0.7, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0};

// RMS of differences about their mean (the offset removed), from their sum, sum of squares and
// count (> 0).
double RmsAboutMean(double sum, double sum2, double count) {
  const double mean = sum / count;
  return std::sqrt(std::max(0.0, sum2 / count - mean * mean));
}

json ReadJsonFile(const fs::path& path, const std::string& what) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string(), "", what);
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw InputError(path.string(), "", "valid JSON (" + std::string(e.what()) + ")");
  }
}

// Local shading frame of a normal turned by an anisotropy rotation (fitting/shading_frame.h, the
// fitter's convention; the truth uses the scene's fibre direction when truth/tangent.exr exists).
void LocalFrame(const Eigen::Vector3d& n, double rotation_deg, Eigen::Vector3d* t, Eigen::Vector3d* b) {
  const fitting::ShadingFrame frame = fitting::MakeShadingFrame(n, rotation_deg);
  *t = frame.tangent;
  *b = frame.bitangent;
}

// Held-out lights: directional, staggered between the usual ring azimuths, at three elevations,
// kept when no capture light is within min_separation_deg.
std::vector<Eigen::Vector3d> HeldOutLights(const json& truth_json, const EvaluateOptions& options) {
  std::vector<Eigen::Vector3d> capture;
  if (truth_json.contains("rig") && truth_json["rig"].contains("lights") && truth_json["rig"]["lights"].is_array()) {
    for (const json& l : truth_json["rig"]["lights"]) {
      const char* key = l.contains("direction") ? "direction" : (l.contains("position_mm") ? "position_mm" : nullptr);
      if (!key || !l[key].is_array() || l[key].size() != 3) continue;
      Eigen::Vector3d d(l[key][0].get<double>(), l[key][1].get<double>(), l[key][2].get<double>());
      if (d.norm() > 0) capture.push_back(d.normalized());
    }
  }
  std::vector<Eigen::Vector3d> out;
  const double min_cos = std::cos(options.min_separation_deg / kRadToDeg);
  for (double elevation_deg : {45.0, 20.0, 75.0}) {
    for (int k = 0; k < 8; ++k) {
      const double azimuth = (22.5 + 45.0 * k + (elevation_deg == 45.0 ? 0.0 : 11.25)) / kRadToDeg;
      const double e = elevation_deg / kRadToDeg;
      const Eigen::Vector3d d(std::cos(e) * std::cos(azimuth), std::cos(e) * std::sin(azimuth), std::sin(e));
      bool clear = true;
      for (const auto& c : capture) clear = clear && d.dot(c) < min_cos;
      if (clear && static_cast<int>(out.size()) < options.max_held_out_lights) out.push_back(d);
    }
  }
  return out;
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "n/a";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

}  // namespace

bool EvaluateOptions::Check(std::string* why) const {
  if (side != "front" && side != "back") {
    if (why) *why = "side must be front or back";
    return false;
  }
  if (max_held_out_lights < 1 || !(min_separation_deg >= 0.0 && min_separation_deg < 90.0)) {
    if (why) *why = "held-out lights: at least one, separation in [0, 90) deg";
    return false;
  }
  return true;
}

Evaluation Evaluate(const fs::path& output_dir, const fs::path& truth_dir, const EvaluateOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw InputError("evaluate options", "", why);
  const TruthMaps truth = ReadTruthMaps(truth_dir);
  const json truth_json = ReadJsonFile(truth_dir / "truth.json", "a readable truth.json");

  // The output grid, from the run's report.
  const fs::path report_path = output_dir / "report.json";
  const json report = ReadJsonFile(report_path, "the report.json of a `u3mscan process` run");
  const json* grid = nullptr;
  if (report.contains("calibration") && report["calibration"].contains("grid")) grid = &report["calibration"]["grid"];
  if (!grid || !grid->contains("pitch_mm") || !grid->contains("region_mm") || !(*grid)["region_mm"].is_array() ||
      (*grid)["region_mm"].size() != 4) {
    throw InputError(report_path.string(), "/calibration/grid", "the metric grid (pitch_mm, region_mm [x0, y0, x1, y1])");
  }
  const double pitch_mm = (*grid)["pitch_mm"].get<double>();
  const double x0_mm = (*grid)["region_mm"][0].get<double>(), y1_mm = (*grid)["region_mm"][3].get<double>();
  if (!(pitch_mm > 0)) throw InputError(report_path.string(), "/calibration/grid/pitch_mm", "a positive pitch in mm");

  const std::string prefix = options.side == "front" ? "" : options.side + "_";
  const fs::path maps_dir = output_dir / "maps";
  auto map_path = [&](const std::string& name) { return maps_dir / (prefix + name + ".exr"); };
  auto read_optional = [&](const std::string& name) -> Image {
    return fs::exists(map_path(name)) ? ReadImageFile(map_path(name), PixelEncoding::kLinear) : Image();
  };
  if (!fs::exists(map_path("normal"))) {
    throw InputError(map_path("normal").string(), "", "the debug maps of the run (`u3mscan process --debug-maps`)");
  }
  const Image normal = ReadImageFile(map_path("normal"), PixelEncoding::kLinear);
  const int w = normal.width(), h = normal.height();
  auto check_size = [&](const Image& image, const std::string& name, int channels) {
    if (image.empty()) return;
    if (image.width() != w || image.height() != h || image.channels() < channels) {
      throw InputError(map_path(name).string(), "", std::to_string(w) + "x" + std::to_string(h) + " with " +
                                                        std::to_string(channels) + " channel(s), like normal.exr");
    }
  };
  if (normal.channels() < 3) throw InputError(map_path("normal").string(), "", "3 channels (x, y, z)");
  const Image albedo = read_optional("albedo");
  const Image height = read_optional("height");
  Image base_color = read_optional("base_color");
  check_size(albedo, "albedo", 3);
  check_size(height, "height", 1);
  check_size(base_color, "base_color", 3);
  // The fit's anisotropy rotation (degrees): its map where the run wrote one, else the material's
  // constant (below), else 0.
  const Image rotation_map = read_optional("anisotropy_rotation");
  check_size(rotation_map, "anisotropy_rotation", 1);
  if (base_color.empty()) base_color = albedo;  // what the writer uses when the fit gives none
  const long long expected_w = std::llround(((*grid)["region_mm"][2].get<double>() - x0_mm) / pitch_mm);
  if (expected_w != w) {
    throw InputError(map_path("normal").string(), "", "a width of " + std::to_string(expected_w) + " pixels (report.json /calibration/grid)");
  }

  // Fitted parameters: the per-pixel map when the run wrote one, else the material's constant.
  std::map<std::string, std::pair<std::string, double>> written;  // u3m key -> (source, value)
  std::map<std::string, bool> reliable;                            // u3m key -> report's verdict
  if (report.contains("parameters") && report["parameters"].is_array()) {
    for (const json& p : report["parameters"]) {
      const std::string name = p.value("name", std::string());
      if (name.rfind(options.side + "/", 0) != 0) continue;
      written[name.substr(options.side.size() + 1)] = {p.value("source", std::string()), p.value("value", 0.0)};
      reliable[name.substr(options.side.size() + 1)] = p.value("reliable", true);
    }
  }
  double rotation_constant_deg = 0.0;
  if (const auto it = written.find("anisotropy_rotation"); it != written.end() && it->second.first.rfind("not measured", 0) != 0) {
    rotation_constant_deg = it->second.second;
  }
  Image estimate_maps[kParameterCount];
  Evaluation ev;
  ev.scene = truth.scene;
  ev.side = options.side;
  ev.width = w;
  ev.height = h;
  double constants[kParameterCount];
  for (int p = 0; p < kParameterCount; ++p) {
    ParameterError e;
    e.name = kParameterNames[p];
    e.u3m_key = kU3mKeys[p];
    constants[p] = kU3mDefaults[p];
    const auto it = written.find(e.u3m_key);
    const bool not_measured = it != written.end() && it->second.first.rfind("not measured", 0) == 0;
    estimate_maps[p] = read_optional(e.name);
    check_size(estimate_maps[p], e.name, 1);
    if (it != written.end()) constants[p] = it->second.second;
    if (reliable.count(e.u3m_key)) e.reliable = reliable[e.u3m_key];
    if (not_measured) {
      e.source = "not measured";
      estimate_maps[p] = Image();
    } else if (!estimate_maps[p].empty()) {
      e.source = "map";
      e.measured = true;
    } else if (it != written.end()) {
      e.source = "constant";
      e.measured = true;
    } else {
      e.source = "absent";
    }
    ev.parameters.push_back(e);
  }

  // Which truth pixels each output pixel is compared with (bench/truth_footprint.h).
  const TruthFootprint footprint(truth, x0_mm, y1_mm, pitch_mm);
  const std::vector<Eigen::Vector3d> lights = HeldOutLights(truth_json, options);
  ev.held_out_lights = static_cast<int>(lights.size());
  const Eigen::Vector3d view_in_world = Eigen::Vector3d::UnitZ();

  // The truth over a set of taps: normal (unit), shading frame (the scene's fibre direction, as the
  // renderer shades it, where truth/tangent.exr exists) and Principled parameters.
  struct TruthPoint {
    Eigen::Vector3d normal, tangent, bitangent;
    PrincipledParams<double> params;
  };
  auto truth_at = [&](const std::vector<TruthTap>& taps, TruthPoint* t) {
    t->normal = Eigen::Vector3d(TapMean(truth.normal, 0, taps), TapMean(truth.normal, 1, taps), TapMean(truth.normal, 2, taps));
    if (!(t->normal.norm() > 0)) return false;
    t->normal.normalize();
    LocalFrame(t->normal, 0.0, &t->tangent, &t->bitangent);
    if (!truth.tangent.empty()) {
      Eigen::Vector3d fibre(TapMean(truth.tangent, 0, taps), TapMean(truth.tangent, 1, taps), TapMean(truth.tangent, 2, taps));
      fibre -= fibre.dot(t->normal) * t->normal;
      if (fibre.squaredNorm() > 1e-12) {
        t->tangent = fibre.normalized();
        t->bitangent = t->normal.cross(t->tangent);
      }
    }
    t->params.base_color = Eigen::Vector3d(TapMean(truth.base_color, 0, taps), TapMean(truth.base_color, 1, taps), TapMean(truth.base_color, 2, taps));
    double* fields[kParameterCount] = {&t->params.roughness,  &t->params.specular,    &t->params.specular_tint,
                                       &t->params.sheen,      &t->params.sheen_tint,  &t->params.anisotropic,
                                       &t->params.metallic};
    // A truth folder without the map means the scene has the U3M default there.
    for (int p = 0; p < kParameterCount; ++p) *fields[p] = truth.parameters[p].empty() ? kU3mDefaults[p] : TapMean(truth.parameters[p], 0, taps);
    return true;
  };
  // Radiance f(L, V) cos_l for a unit light from world direction l, the view straight above, in the
  // shading frame (t, b, n). `render` is a Principled material's (the fit, and the truth's own maps
  // as a material); `render_truth` is the fabric's: the model its scene was rendered with
  // (truth.json /reflectance_model). Under model mismatch (the synthetic scanner's Charlie sheen,
  // datasets_synthetic/renderer.h, evaluated in float as the renderer does) the re-render then
  // compares the material with what the fabric looks like, not with a Principled rendering of the
  // truth's parameters.
  auto in_frame = [](const Eigen::Vector3d& d, const Eigen::Vector3d& n, const Eigen::Vector3d& t, const Eigen::Vector3d& b) {
    return Eigen::Vector3d(d.dot(t), d.dot(b), d.dot(n));
  };
  auto render = [&](const PrincipledParams<double>& params, const Eigen::Vector3d& n, const Eigen::Vector3d& t,
                    const Eigen::Vector3d& b, const Eigen::Vector3d& l) -> Eigen::Vector3d {
    const Eigen::Vector3d ll = in_frame(l, n, t, b), vl = in_frame(view_in_world, n, t, b);
    return EvaluatePrincipled(params, ll, vl) * std::max(0.0, ll.z());
  };
  const bool truth_is_principled = truth.model == synthetic::ReflectanceModel::kPrincipled;
  ev.truth_reflectance_model = synthetic::ReflectanceModelName(truth.model);
  auto render_truth = [&](const PrincipledParams<double>& params, const Eigen::Vector3d& n, const Eigen::Vector3d& t,
                          const Eigen::Vector3d& b, const Eigen::Vector3d& l) -> Eigen::Vector3d {
    if (truth_is_principled) return render(params, n, t, b, l);
    const Eigen::Vector3d ll = in_frame(l, n, t, b), vl = in_frame(view_in_world, n, t, b);
    PrincipledParams<float> p;
    p.base_color = params.base_color.cast<float>();
    p.roughness = static_cast<float>(params.roughness);
    p.specular = static_cast<float>(params.specular);
    p.specular_tint = static_cast<float>(params.specular_tint);
    p.sheen = static_cast<float>(params.sheen);
    p.sheen_tint = static_cast<float>(params.sheen_tint);
    p.anisotropic = static_cast<float>(params.anisotropic);
    p.metallic = static_cast<float>(params.metallic);
    const Vec3<float> f = synthetic::EvaluateModel(truth.model, p, ll.cast<float>(), vl.cast<float>());
    return f.cast<double>() * std::max(0.0, ll.z());
  };

  // The run's levelling: the truth's height is then kept on the output grid (4 bytes a pixel) and
  // levelled the same way for the second height figure.
  reconstruction::Levelling levelling = reconstruction::Levelling::kNone;
  if (report.contains("options") && report["options"].is_object() && report["options"].contains("levelling")) {
    const json& field = report["options"]["levelling"];
    try {
      levelling = reconstruction::ParseLevelling(field.is_string() ? field.get<std::string>() : field.dump());
    } catch (const std::invalid_argument&) {
      throw InputError(report_path.string(), "/options/levelling", "none, plane or quadratic");
    }
  }
  Image truth_height_on_grid;
  if (levelling != reconstruction::Levelling::kNone && !height.empty()) {
    truth_height_on_grid = Image(w, h, 1, NAN, pitch_mm);
  }

  // Per-pixel errors (NaN where not compared), then summaries.
  const std::size_t n = static_cast<std::size_t>(w) * h;
  // Per pixel only what needs percentiles (12 bytes a pixel); everything else is summed per row,
  // so a 36-megapixel output needs no per-pixel parameter or render buffers.
  std::vector<float> angle(n, NAN), de_albedo(n, NAN), de_base(n, NAN);
  struct RowSums {
    double height_d = 0, height_d2 = 0, height_lo = INFINITY, height_hi = -INFINITY;
    long long height_count = 0;
    double truth[kParameterCount] = {}, estimate[kParameterCount] = {}, abs_error[kParameterCount] = {};
    long long parameter_count = 0;
    double render_num = 0, render_den = 0, truth_maps_num = 0;
  };
  std::vector<RowSums> row_sums(static_cast<std::size_t>(h));
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    std::vector<TruthTap> taps, one_tap(1);  // reused for every pixel of the chunk
    std::vector<Eigen::Vector3d> truth_radiance(lights.size());
    for (std::size_t row = begin; row < end; ++row) {
      RowSums& sums = row_sums[row];
      for (int col = 0; col < w; ++col) {
        const std::size_t i = row * w + col;
        if (!footprint.Gather(col, static_cast<int>(row), &taps)) continue;
        TruthPoint tp;
        if (!truth_at(taps, &tp)) continue;
        Eigen::Vector3d ne(normal.at(0, row, col), normal.at(1, row, col), normal.at(2, row, col));
        if (!(ne.norm() > 0) || !ne.allFinite()) continue;
        const Eigen::Vector3d& nt = tp.normal;
        ne.normalize();
        angle[i] = static_cast<float>(std::atan2(nt.cross(ne).norm(), nt.dot(ne)) * kRadToDeg);
        const Rgb truth_rgb{static_cast<float>(tp.params.base_color[0]), static_cast<float>(tp.params.base_color[1]),
                            static_cast<float>(tp.params.base_color[2])};
        const Lab truth_lab = LinearSrgbToLab(truth_rgb);
        if (!albedo.empty()) {
          de_albedo[i] = static_cast<float>(Ciede2000(truth_lab, LinearSrgbToLab({albedo.at(0, row, col), albedo.at(1, row, col), albedo.at(2, row, col)})));
        }
        if (!base_color.empty()) {
          de_base[i] = static_cast<float>(Ciede2000(truth_lab, LinearSrgbToLab({base_color.at(0, row, col), base_color.at(1, row, col), base_color.at(2, row, col)})));
        }
        if (!height.empty()) {
          const double truth_h = TapMean(truth.height_mm, 0, taps), d = height.at(0, row, col) - truth_h;
          if (std::isfinite(d)) {
            if (!truth_height_on_grid.empty()) truth_height_on_grid.at(0, row, col) = static_cast<float>(truth_h);
            sums.height_d += d;
            sums.height_d2 += d * d;
            sums.height_lo = std::min(sums.height_lo, truth_h);
            sums.height_hi = std::max(sums.height_hi, truth_h);
            ++sums.height_count;
          }
        }
        PrincipledParams<double> fit_params;
        if (!base_color.empty()) {
          fit_params.base_color = Eigen::Vector3d(base_color.at(0, row, col), base_color.at(1, row, col), base_color.at(2, row, col));
        }
        const double truth_fields[kParameterCount] = {tp.params.roughness,  tp.params.specular,    tp.params.specular_tint,
                                                      tp.params.sheen,      tp.params.sheen_tint,  tp.params.anisotropic,
                                                      tp.params.metallic};
        double* fit_fields[kParameterCount] = {&fit_params.roughness,  &fit_params.specular,    &fit_params.specular_tint,
                                               &fit_params.sheen,      &fit_params.sheen_tint,  &fit_params.anisotropic,
                                               &fit_params.metallic};
        for (int p = 0; p < kParameterCount; ++p) {
          const double t = truth_fields[p];
          const double e = estimate_maps[p].empty() ? constants[p] : estimate_maps[p].at(0, row, col);
          *fit_fields[p] = e;
          sums.truth[p] += t;
          sums.estimate[p] += e;
          sums.abs_error[p] += std::abs(e - t);
        }
        ++sums.parameter_count;
        // The truth's radiance under each held-out light: of the interpolated truth (bilinear), or
        // the area-weighted mean of each truth pixel's own (footprints: what a photograph of the
        // coarser pixel would hold).
        bool truth_finite = true;
        if (!footprint.averages_footprints()) {
          for (std::size_t k = 0; k < lights.size(); ++k) {
            truth_radiance[k] = render_truth(tp.params, nt, tp.tangent, tp.bitangent, lights[k]);
          }
        } else {
          for (auto& r : truth_radiance) r.setZero();
          for (const TruthTap& tap : taps) {
            one_tap[0] = {tap.col, tap.row, 1.0f};
            TruthPoint at_tap;
            if (!truth_at(one_tap, &at_tap)) {
              truth_finite = false;
              break;
            }
            for (std::size_t k = 0; k < lights.size(); ++k) {
              truth_radiance[k] += tap.weight * render_truth(at_tap.params, at_tap.normal, at_tap.tangent, at_tap.bitangent, lights[k]);
            }
          }
        }
        if (!truth_finite) continue;
        Eigen::Vector3d et, eb;
        LocalFrame(ne, rotation_map.empty() ? rotation_constant_deg : rotation_map.at(0, row, col), &et, &eb);
        double num = 0, den = 0, truth_maps_num = 0;
        for (std::size_t k = 0; k < lights.size(); ++k) {
          const Eigen::Vector3d& rt = truth_radiance[k];
          const Eigen::Vector3d re = render(fit_params, ne, et, eb, lights[k]);
          if (!re.allFinite() || !rt.allFinite()) continue;
          num += (re - rt).squaredNorm();
          den += rt.squaredNorm();
          // The truth's own maps on this grid as a Principled material, rendered as one pixel
          // (Evaluation::rerender_truth_maps_relative_rmse); that is rt itself on a grid no coarser
          // than a Principled truth's.
          const bool maps_render_as_truth = !footprint.averages_footprints() && truth_is_principled;
          const Eigen::Vector3d rm = maps_render_as_truth ? rt : render(tp.params, nt, tp.tangent, tp.bitangent, lights[k]);
          if (rm.allFinite()) truth_maps_num += (rm - rt).squaredNorm();
        }
        sums.render_num += num;
        sums.render_den += den;
        sums.truth_maps_num += truth_maps_num;
      }
    }
  });

  for (std::size_t i = 0; i < n; ++i) ev.pixels_compared += std::isfinite(angle[i]) ? 1 : 0;
  if (ev.pixels_compared == 0) {
    throw InputError(truth_dir.string(), "", "a truth grid that overlaps the output's metric grid (report.json /calibration/grid)");
  }
  const ErrorStats normal_stats = Summarise(angle);
  ev.normal_mean_deg = normal_stats.mean;
  ev.normal_median_deg = normal_stats.median;
  ev.normal_p95_deg = normal_stats.p95;
  const ErrorStats a = Summarise(de_albedo);
  ev.albedo_de_mean = a.mean;
  ev.albedo_de_median = a.median;
  ev.albedo_de_p95 = a.p95;
  const ErrorStats b = Summarise(de_base);
  ev.base_color_de_mean = b.mean;
  ev.base_color_de_median = b.median;
  ev.base_color_de_p95 = b.p95;

  // Height: remove the mean offset (integration fixes height only up to a constant).
  RowSums all;
  for (const RowSums& r : row_sums) {
    all.height_d += r.height_d;
    all.height_d2 += r.height_d2;
    all.height_lo = std::min(all.height_lo, r.height_lo);
    all.height_hi = std::max(all.height_hi, r.height_hi);
    all.height_count += r.height_count;
    for (int p = 0; p < kParameterCount; ++p) {
      all.truth[p] += r.truth[p];
      all.estimate[p] += r.estimate[p];
      all.abs_error[p] += r.abs_error[p];
    }
    all.parameter_count += r.parameter_count;
    all.render_num += r.render_num;
    all.render_den += r.render_den;
    all.truth_maps_num += r.truth_maps_num;
  }
  if (all.height_count > 0) {
    ev.height_rmse_mm = RmsAboutMean(all.height_d, all.height_d2, static_cast<double>(all.height_count));
    ev.height_range_mm = all.height_hi - all.height_lo;
    ev.height_rmse_percent = ev.height_range_mm > 0 ? 100.0 * ev.height_rmse_mm / ev.height_range_mm : kNaN;
  } else {
    ev.height_rmse_mm = ev.height_range_mm = ev.height_rmse_percent = kNaN;
  }
  ev.height_levelling = reconstruction::LevellingName(levelling);
  if (!truth_height_on_grid.empty() && all.height_count > 0) {
    // Pixels not compared are NaN in the truth: they weigh 0 in the levelling and are skipped here.
    reconstruction::LevelRelief(levelling, &truth_height_on_grid, nullptr);
    double sum = 0.0, sum2 = 0.0;
    long long count = 0;
    for (int row = 0; row < h; ++row)
      for (int col = 0; col < w; ++col) {
        const double d = static_cast<double>(height.at(0, row, col)) - truth_height_on_grid.at(0, row, col);
        if (!std::isfinite(d)) continue;
        sum += d;
        sum2 += d * d;
        ++count;
      }
    if (count > 0) {
      ev.height_levelled_rmse_mm = RmsAboutMean(sum, sum2, static_cast<double>(count));
      ev.height_levelled_rmse_percent =
          ev.height_range_mm > 0 ? 100.0 * ev.height_levelled_rmse_mm / ev.height_range_mm : kNaN;
    }
  }

  for (int p = 0; p < kParameterCount; ++p) {
    ParameterError& e = ev.parameters[p];
    const double m = static_cast<double>(all.parameter_count);
    e.truth_mean = m > 0 ? all.truth[p] / m : kNaN;
    e.estimate_mean = m > 0 ? all.estimate[p] / m : kNaN;
    e.mean_abs_error = e.measured && m > 0 ? all.abs_error[p] / m : kNaN;
    e.bias = e.measured && m > 0 ? e.estimate_mean - e.truth_mean : kNaN;
  }
  const double num = all.render_num, den = all.render_den;
  ev.rerender_relative_rmse = den > 0 ? std::sqrt(num / den) : kNaN;
  ev.rerender_truth_maps_relative_rmse = den > 0 ? std::sqrt(all.truth_maps_num / den) : kNaN;
  return ev;
}

json EvaluationToJson(const Evaluation& ev) {
  json parameters = json::array();
  for (const auto& p : ev.parameters) {
    parameters.push_back({{"name", p.name}, {"u3m_key", p.u3m_key}, {"source", p.source}, {"measured", p.measured},
                          {"reliable", p.reliable}, {"truth_mean", FiniteOrNull(p.truth_mean)}, {"estimate_mean", FiniteOrNull(p.estimate_mean)},
                          {"mean_abs_error", FiniteOrNull(p.mean_abs_error)}, {"bias", FiniteOrNull(p.bias)}});
  }
  return {{"scene", ev.scene},
          {"side", ev.side},
          {"grid", {{"width", ev.width}, {"height", ev.height}}},
          {"pixels_compared", ev.pixels_compared},
          {"normal_error_deg", {{"mean", FiniteOrNull(ev.normal_mean_deg)}, {"median", FiniteOrNull(ev.normal_median_deg)}, {"p95", FiniteOrNull(ev.normal_p95_deg)}}},
          {"albedo_ciede2000", {{"mean", FiniteOrNull(ev.albedo_de_mean)}, {"median", FiniteOrNull(ev.albedo_de_median)}, {"p95", FiniteOrNull(ev.albedo_de_p95)}}},
          {"base_color_ciede2000", {{"mean", FiniteOrNull(ev.base_color_de_mean)}, {"median", FiniteOrNull(ev.base_color_de_median)}, {"p95", FiniteOrNull(ev.base_color_de_p95)}}},
          {"height", {{"rmse_mm", FiniteOrNull(ev.height_rmse_mm)}, {"range_mm", FiniteOrNull(ev.height_range_mm)}, {"rmse_percent_of_range", FiniteOrNull(ev.height_rmse_percent)},
                      {"truth_levelled", {{"levelling", ev.height_levelling}, {"rmse_mm", FiniteOrNull(ev.height_levelled_rmse_mm)},
                                          {"rmse_percent_of_range", FiniteOrNull(ev.height_levelled_rmse_percent)}}}}},
          {"parameters", parameters},
          {"rerender", {{"held_out_lights", ev.held_out_lights}, {"truth_reflectance_model", ev.truth_reflectance_model},
                        {"relative_rmse", FiniteOrNull(ev.rerender_relative_rmse)},
                        {"truth_maps_relative_rmse", FiniteOrNull(ev.rerender_truth_maps_relative_rmse)}}}};
}

const ParameterError& FindParameter(const Evaluation& evaluation, const std::string& name) {
  for (const ParameterError& p : evaluation.parameters) {
    if (p.name == name) return p;
  }
  throw std::out_of_range("FindParameter: no parameter " + name + " in the evaluation");
}

std::string EvaluationToText(const Evaluation& ev) {
  std::ostringstream s;
  s << "side " << ev.side << ": " << ev.width << "x" << ev.height << " grid, " << ev.pixels_compared << " pixels compared\n";
  s << "normal angular error (deg)   mean " << Fixed(ev.normal_mean_deg, 3) << "  median " << Fixed(ev.normal_median_deg, 3)
    << "  p95 " << Fixed(ev.normal_p95_deg, 3) << "\n";
  s << "albedo CIEDE2000             mean " << Fixed(ev.albedo_de_mean, 3) << "  median " << Fixed(ev.albedo_de_median, 3)
    << "  p95 " << Fixed(ev.albedo_de_p95, 3) << "\n";
  s << "base colour CIEDE2000        mean " << Fixed(ev.base_color_de_mean, 3) << "  median " << Fixed(ev.base_color_de_median, 3)
    << "  p95 " << Fixed(ev.base_color_de_p95, 3) << "\n";
  s << "height RMSE (offset removed) " << Fixed(ev.height_rmse_mm * 1000.0, 2) << " um = " << Fixed(ev.height_rmse_percent, 2)
    << " % of the " << Fixed(ev.height_range_mm * 1000.0, 1) << " um range\n";
  if (ev.height_levelling != "none") {
    s << "height RMSE, truth levelled (" << ev.height_levelling << ", as the run) " << Fixed(ev.height_levelled_rmse_mm * 1000.0, 2)
      << " um = " << Fixed(ev.height_levelled_rmse_percent, 2) << " % of the same range\n";
  }
  for (const auto& p : ev.parameters) {
    s << "  " << std::left << std::setw(14) << p.name << std::right;
    if (!p.measured) {
      s << p.source << " (material " << Fixed(p.estimate_mean, 3) << ", truth mean " << Fixed(p.truth_mean, 3) << ")\n";
    } else {
      s << "|error| " << Fixed(p.mean_abs_error, 4) << "  bias " << Fixed(p.bias, 4) << "  (" << p.source << ", mean "
        << Fixed(p.estimate_mean, 3) << ", truth " << Fixed(p.truth_mean, 3) << ")"
        << (p.reliable ? "" : "  flagged unreliable by the run") << "\n";
    }
  }
  s << "re-render, " << ev.held_out_lights << " held-out lights: relative RMSE " << Fixed(100.0 * ev.rerender_relative_rmse, 2)
    << " % (the truth's own maps on this grid: " << Fixed(100.0 * ev.rerender_truth_maps_relative_rmse, 2) << " %)";
  if (ev.truth_reflectance_model != "principled") {
    s << "; the truth rendered with its scene's model, " << ev.truth_reflectance_model << " (model mismatch)";
  }
  s << "\n";
  return s.str();
}

}  // namespace u3mscan::bench
