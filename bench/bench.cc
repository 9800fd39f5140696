#include "bench/bench.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>

#include "bench/issue_targets.h"
#include "bench/svg_plot.h"
#include "bench/table_cells.h"
#include "bench/truth_maps.h"
#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/text_file.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"
#include "datasets_synthetic/synth_run.h"
#include "datasets_synthetic/truth_writer.h"

extern char** environ;

namespace u3mscan::bench {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// Fixed id and time, so every run writes the same material (process.h).
constexpr const char* kRunId = "00000000-0000-4000-8000-000000000000";
constexpr const char* kRunCreated = "2026-01-01T00:00:00Z";
constexpr double kDpi = 300.0;

std::string Join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : separator) + item;
  return out;
}

// Lights of a rig subset to `count`, spread evenly over the list (which runs ring by ring), so the
// subset keeps every elevation.
void SubsetLights(synthetic::Rig* rig, int count) {
  if (count <= 0 || count >= static_cast<int>(rig->lights.size())) return;
  std::vector<synthetic::RigLight> kept;
  const int n = static_cast<int>(rig->lights.size());
  for (int k = 0; k < count; ++k) kept.push_back(rig->lights[static_cast<std::size_t>(k) * n / count]);
  rig->lights = std::move(kept);
}

// Renders the case's capture (and its truth) unless it exists; returns its folder.
fs::path EnsureCapture(const BenchCase& c, const BenchOptions& options, int* lights_out) {
  const fs::path dir = options.out_dir / "work" / "captures" / c.CaptureId();
  synthetic::RigOptions rig_options;
  const int camera_px = c.size_px * c.camera_per_map;
  rig_options.width = camera_px;
  rig_options.height = camera_px;
  rig_options.pitch_mm = 25.4 / (kDpi * c.camera_per_map);
  rig_options.seed = options.seed;
  synthetic::Rig rig = synthetic::MakeRig(c.rig, rig_options);
  rig.sensor.noise = c.sensor_noise;
  SubsetLights(&rig, c.lights);
  *lights_out = static_cast<int>(rig.lights.size());
  if (fs::exists(dir / synthetic::kCaptureSubdir / "capture.json")) return dir;
  fs::remove_all(dir);
  synthetic::SceneOptions scene_options;
  scene_options.width = scene_options.height = std::max(8, static_cast<int>(std::lround(synthetic::kSampleFillOfView * camera_px)));
  scene_options.pitch_mm = rig_options.pitch_mm;
  scene_options.seed = options.seed;
  // Rendered as `u3mscan synth` does (synth_run.h): a finer sampling of the fabric seen through an
  // area-integrating camera, the truth being its area average on the output grid, so the error the
  // bench reports is the pipeline's and not the point-sampled renderer's aliasing.
  const int supersample = synthetic::AutoSupersample(camera_px, camera_px);
  const synthetic::OversampledScene scene = synthetic::MakeOversampledScene(c.scene, scene_options, supersample);
  synthetic::CaptureOptions capture;
  capture.format = synthetic::FrameFormat::kTiff;  // the decoded values; DNG decoding is not what we time
  capture.calibration_frames = c.calibration_frames;
  capture.supersample = supersample;
  fs::create_directories(dir.parent_path());
  // Default truth writer: maps + truth.json with the rig.
  synthetic::WriteSyntheticCapture(scene.fine, scene.truth, rig, capture, dir);
  return dir;
}

struct ChildResult {
  int exit_code = -1;
  double wall_s = 0;
  double max_rss_mib = 0;
};

// Runs argv[0] with argv, stdout and stderr into log_path; waits with wait4 for its rusage.
ChildResult RunChild(const std::vector<std::string>& args, const fs::path& log_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  ChildResult result;
  const double start = SteadySeconds();
  pid_t pid = 0;
  const int spawn_error = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawn_error != 0) throw InputError(args[0], "", "an executable u3mscan binary (posix_spawn failed)");
  int status = 0;
  struct rusage usage {};
  while (wait4(pid, &status, 0, &usage) < 0) {
    if (errno != EINTR) throw std::runtime_error("wait4 failed");
  }
  result.wall_s = SteadySeconds() - start;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  result.max_rss_mib = static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: KiB
  return result;
}

std::string LastLines(const fs::path& path, std::size_t count) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  if (lines.size() > count) lines.erase(lines.begin(), lines.end() - static_cast<std::ptrdiff_t>(count));
  return Join(lines, " | ");
}

void ReadReport(const fs::path& report_path, BenchRow* row) {
  std::ifstream in(report_path);
  if (!in) throw InputError(report_path.string(), "", "the report.json of the run");
  const json report = json::parse(in);
  row->total_s = report.value("total_seconds", 0.0);
  if (report.contains("options")) {
    row->solver_used = report["options"].value("solver", std::string());
    row->integrator_used = report["options"].value("integrator", std::string());
    row->fit_mode_used = report["options"].value("fit_mode", std::string());
  }
  for (const json& parameter : report.value("parameters", json::array())) {
    if (!parameter.value("reliable", true)) row->unreliable.push_back(parameter.value("name", std::string()));
  }
  const json held = report.value("/quality/front/held_out_lights/relative_rmse"_json_pointer, json());
  if (held.is_number()) row->held_out_rmse = held.get<double>();
  StageSeconds& s = row->stages;
  // Per-light calibration steps are counted, not listed ("calibration: light x12").
  int lights_skipped = 0;
  for (const json& step : report.value("steps", json::array())) {
    const std::string name = step.value("name", std::string());
    const double seconds = step.value("seconds", 0.0);
    if (!step.value("ran", false)) {
      if (name.rfind("calibration: light ", 0) == 0) ++lights_skipped;
      else row->skipped.push_back(name);
      continue;
    }
    auto starts = [&](const char* prefix) { return name.rfind(prefix, 0) == 0; };
    if (starts("read manifest")) s.read += seconds;
    else if (starts("calibration (total)")) s.calibration += seconds;
    else if (starts("rectify")) s.rectify += seconds;
    else if (starts("alpha")) s.alpha += seconds;
    else if (starts("photometric stereo")) s.photometric_stereo += seconds;
    else if (starts("integration")) s.integration += seconds;
    else if (starts("fit")) s.fit += seconds;
    else if (starts("write U3M")) s.write += seconds;
  }
  if (lights_skipped > 0) row->skipped.push_back("calibration: light x" + std::to_string(lights_skipped));
}

BenchRow RunCase(const BenchCase& c, const BenchOptions& options) {
  BenchRow row;
  row.c = c;
  const fs::path capture_root = EnsureCapture(c, options, &row.lights_used);
  const fs::path run_dir = options.out_dir / "work" / "runs" / c.RunId();
  fs::remove_all(run_dir);
  fs::create_directories(run_dir.parent_path());
  std::vector<std::string> args = {options.executable.string(), "process", (capture_root / synthetic::kCaptureSubdir).string(),
                                   "-o", run_dir.string(), "--preset", c.preset, "--debug-maps", "--quiet",
                                   "--id", kRunId, "--created", kRunCreated};
  if (!c.solver.empty()) args.insert(args.end(), {"--solver", c.solver});
  if (!c.integrator.empty()) args.insert(args.end(), {"--integrator", c.integrator});
  if (!c.fit_mode.empty()) args.insert(args.end(), {"--fit-mode", c.fit_mode});
  if (!c.hold_out_lights.empty()) args.insert(args.end(), {"--hold-out-lights", c.hold_out_lights});
  // A camera finer than the maps: the maps stay at the matrix's dpi (the capture's own is finer),
  // unless the case asks for them at the camera's.
  if (c.camera_per_map > 1) args.insert(args.end(), {"--dpi", Fixed(c.MapsDpi(), 0)});
  args.insert(args.end(), {"--ps-supersample", std::to_string(c.ps_supersample)});  // the case's, not the default
  args.insert(args.end(), {"--level", c.level});
  if (c.follow_fibres) args.push_back("--follow-fibres");
  if (options.threads > 0) args.insert(args.end(), {"--threads", std::to_string(options.threads)});
  const fs::path log_path = run_dir.string() + ".log";
  const ChildResult child = RunChild(args, log_path);
  row.wall_s = child.wall_s;
  row.peak_rss_mib = child.max_rss_mib;
  if (child.exit_code != 0) {
    row.status = "failed";
    row.error = "exit " + std::to_string(child.exit_code) + ": " + LastLines(log_path, 3);
    return row;
  }
  try {
    ReadReport(run_dir / "report.json", &row);
    row.evaluation = Evaluate(run_dir, capture_root / synthetic::kTruthSubdir);
    row.megapixels = static_cast<double>(row.evaluation.width) * row.evaluation.height / 1e6;
  } catch (const std::exception& e) {
    row.status = "failed";
    row.error = e.what();
  }
  return row;
}

std::string ParameterCell(const BenchRow& row, int p) {
  if (row.status != "ok" || p >= static_cast<int>(row.evaluation.parameters.size())) return "";
  const ParameterError& e = row.evaluation.parameters[p];
  return e.measured ? Fixed(e.mean_abs_error, 4) : "not measured";
}

std::string MethodLabel(const BenchRow& r) { return r.solver_used + "/" + r.integrator_used; }

std::string Machine() {
  std::string cpu;
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
  const long cores = sysconf(_SC_NPROCESSORS_ONLN);
  return cpu + ", " + std::to_string(cores) + " cores";
}

std::string UtcDate() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  std::ostringstream s;
  s << std::put_time(&tm, "%Y-%m-%d %H:%M UTC");
  return s.str();
}

}  // namespace

std::vector<std::string> BenchFabricScenes() { return {"plain", "twill", "satin", "knit", "denim", "velvet", "lace"}; }

std::string BenchCase::CaptureId() const {
  std::string id = scene + "_" + rig + "_" + std::to_string(size_px);
  if (lights > 0) id += "_l" + std::to_string(lights);
  if (!calibration_frames) id += "_nocal";
  if (camera_per_map > 1) id += "_cam" + std::to_string(camera_per_map) + "x";
  if (!sensor_noise) id += "_nonoise";
  return id;
}

std::string BenchCase::RunId() const {
  std::string id = CaptureId() + "_" + preset;
  if (!solver.empty()) id += "_ps-" + solver;
  if (!integrator.empty()) id += "_int-" + integrator;
  if (!fit_mode.empty()) id += "_fit-" + fit_mode;
  if (maps_at_camera_dpi && camera_per_map > 1) id += "_maps" + Fixed(MapsDpi(), 0) + "dpi";
  if (ps_supersample != 1) id += "_pss" + std::to_string(ps_supersample);
  if (level != "plane") id += "_level-" + level;
  if (follow_fibres) id += "_fibres";
  if (!hold_out_lights.empty()) {
    std::string ids = hold_out_lights;
    std::replace(ids.begin(), ids.end(), ',', '-');
    id += "_holdout-" + ids;
  }
  return id;
}

double BenchCase::MapsDpi() const { return maps_at_camera_dpi ? kDpi * camera_per_map : kDpi; }

bool BenchOptions::Check(std::string* why) const {
  if (executable.empty()) {
    if (why) *why = "the u3mscan executable for the child runs is not set";
    return false;
  }
  if (threads < 0) {
    if (why) *why = "threads must be >= 0";
    return false;
  }
  return true;
}

std::vector<BenchCase> BenchMatrix(const BenchOptions& options) {
  const std::vector<std::string> presets = {"fast", "balanced", "best"};
  const bool quick = options.quick;
  const int base = quick ? 48 : 128;
  std::vector<BenchCase> cases;
  auto add = [&](BenchCase c) { cases.push_back(std::move(c)); };
  // The matrix: scenes x distant and near lights x every preset. --quick: plain with every preset
  // on the distant rig and fast/balanced on the near one, velvet with fast on the distant rig.
  for (const auto& scene : BenchFabricScenes()) {
    if (quick && scene != "plain" && scene != "velvet") continue;
    for (const char* rig : {"distant", "near"}) {
      for (const auto& preset : presets) {
        if (quick && scene == "velvet" && (preset != "fast" || std::string(rig) != "distant")) continue;
        if (quick && preset == "best" && std::string(rig) == "near") continue;  // best costs 2x balanced
        add({scene, rig, base, 0, true, preset, "", "", "matrix", "", ""});
      }
    }
  }
  // Oblique camera (top + oblique view): sheen becomes measurable. Full: velvet, every preset, and
  // the velvet's material on a smooth relief (velvet_bumps: the sheen the chain recovers where one
  // normal per pixel describes the surface, against the pile's); quick: plain, fast (against
  // plain/near/fast: the time the second view costs).
  if (quick) {
    add({"plain", "oblique", base, 0, true, "fast", "", "", "matrix", "", ""});
  } else {
    for (const auto& preset : presets) add({"velvet", "oblique", base, 0, true, preset, "", "", "matrix", "", ""});
    add({"velvet_bumps", "oblique", base, 0, true, "balanced", "", "", "matrix", "", ""});
  }
  // Model mismatch: the velvet rendered with the synthetic scanner's second reflectance model
  // (Charlie sheen, datasets_synthetic/renderer.h) and fitted with the Principled BRDF, beside the
  // Principled velvet of the same rig and preset (the issue's "report the same figures"). Full:
  // every rig, balanced; quick: the distant rig, fast.
  if (quick) {
    add({"velvet_mismatch", "distant", base, 0, true, "fast", "", "", "model-mismatch", "", ""});
  } else {
    for (const char* rig : {"distant", "near", "oblique"}) {
      add({"velvet_mismatch", rig, base, 0, true, "balanced", "", "", "model-mismatch", "", ""});
    }
  }
  // Methods on the same captures: ls vs robust photometric stereo, dct vs robust integration,
  // clusters vs per-pixel fitting, against the balanced run (robust + dct + per-pixel).
  for (const char* rig : {"distant", "near"}) {
    if (quick && std::string(rig) == "near") continue;
    add({"plain", rig, base, 0, true, "balanced", "ls", "", "methods", "", ""});
    add({"plain", rig, base, 0, true, "balanced", "", "robust", "methods", "", ""});
    add({"plain", rig, base, 0, true, "balanced", "", "", "methods", "clusters", ""});
  }
  // Fit mode on a woven scene with per-thread variation (full matrix: where a texture can pay off).
  if (!quick) add({"twill", "distant", base, 0, true, "balanced", "", "", "methods", "clusters", ""});
  // Held out: four of the 16 lights kept out of the fit and re-rendered against their photographs
  // (the issue's held-out re-render on the captured images, beside the truth-based figure).
  const std::string held_out = "L02,L05,L09,L14";
  add({"plain", "distant", base, 0, true, quick ? "fast" : "balanced", "", "", "held-out", "", held_out});
  if (!quick) {
    add({"plain", "near", base, 0, true, "balanced", "", "", "held-out", "", held_out});
    add({"satin", "distant", base, 0, true, "balanced", "", "", "held-out", "", held_out});
    // Under model mismatch the photographs are the only reference the fit's lobes can be judged by.
    add({"velvet_mismatch", "distant", base, 0, true, "balanced", "", "", "held-out", "", held_out});
    // The same plain photographed at 4x the maps' dpi, its maps at 300 dpi and at the camera's
    // 1200: the 2 % is a matter of maps that resolve the weave (docs/fitting.md, "Maps at the
    // camera's resolution").
    BenchCase fine{"plain", "distant", base, 0, true, "balanced", "", "", "held-out", "", held_out};
    fine.camera_per_map = 4;
    fine.ps_supersample = 0;  // the default of `process`
    add(fine);
    fine.maps_at_camera_dpi = true;
    add(fine);
    // Both exposed without sensor noise too, beside the 1x plain: the material's own error under
    // new lights, which the photographs' noise (about 1.7 % here) hides.
    BenchCase clean{"plain", "distant", base, 0, true, "balanced", "", "", "held-out", "", held_out};
    clean.sensor_noise = false;
    add(clean);
    fine.sensor_noise = false;
    add(fine);
  }
  // Camera finer than the maps: the same sample photographed at 2x (and 3x and 4x, full) the maps' dpi,
  // processed at the matrix's dpi, against the matrix run at 1x (docs/calibration.md, "Footprint
  // pre-filter").
  // Each also with photometric stereo on the camera's grid (--ps-supersample 0).
  // Plain also with --level quadratic on the camera's grid: the bowl that the view-dependent lobes
  // leave in a glossy weave's heights (docs/process.md, "Levelling").
  auto finer = [&](const std::string& scene, const std::string& preset, int factor) {
    BenchCase c{scene, "distant", base, 0, true, preset, "", "", "camera-finer", "", ""};
    c.camera_per_map = factor;
    add(c);
    c.ps_supersample = 0;
    add(c);
    if (scene == "plain") {
      c.level = "quadratic";
      add(c);
    }
  };
  if (quick) {
    finer("plain", "fast", 2);
  } else {
    for (const char* scene : {"plain", "satin", "velvet"}) finer(scene, "balanced", 2);
    finer("plain", "balanced", 3);
    // A 36-megapixel camera over a 15 cm sample: about 1200 dpi, four times 300 dpi maps.
    finer("plain", "balanced", 4);
    // Every fabric there on both rigs (plain/distant above), solved on the camera's grid only (as
    // `process` does by default): which of the issues' targets that camera meets on each
    // (bench.md, "Against the issues' targets").
    for (const auto& scene : BenchFabricScenes()) {
      for (const char* rig : {"distant", "near"}) {
        if (scene == "plain" && std::string(rig) == "distant") continue;
        BenchCase c{scene, rig, base, 0, true, "balanced", "", "", "camera-finer", "", ""};
        c.camera_per_map = 4;
        c.ps_supersample = 0;
        add(c);
      }
    }
    // The fabrics whose stretch turns within a cluster (a lace's cord round its motif, a satin's
    // floats, a twill's warp) with --follow-fibres, beside their runs above.
    for (const char* scene : {"satin", "lace", "twill"}) {
      BenchCase c{scene, "distant", base, 0, true, "balanced", "", "", "fibres", "", ""};
      c.camera_per_map = 4;
      c.ps_supersample = 0;
      c.follow_fibres = true;
      add(c);
    }
  }
  // Needs less: the same scene without calibration frames (no dark, flat, sphere, board, chart).
  add({"plain", "distant", base, 0, false, quick ? "fast" : "balanced", "", "", "needs-less", "", ""});
  if (!quick) add({"plain", "near", base, 0, false, "balanced", "", "", "needs-less", "", ""});
  // Megapixel axis (with the base size of the matrix).
  for (int size : quick ? std::vector<int>{80} : std::vector<int>{256, 512}) {
    for (const char* preset : {"fast", "balanced"}) {
      if (quick && std::string(preset) != "fast") continue;
      add({"plain", "distant", size, 0, true, preset, "", "", "size", "", ""});
    }
  }
  // Lights axis (the rigs have 16).
  for (int lights : quick ? std::vector<int>{8} : std::vector<int>{6, 8, 12}) {
    for (const char* preset : {"fast", "balanced"}) {
      if (quick && std::string(preset) != "fast") continue;
      add({"plain", "distant", base, lights, true, preset, "", "", "lights", "", ""});
    }
  }
  return cases;
}

std::vector<std::string> BenchCsvColumns() {
  return {"group", "scene", "rig", "size_px", "camera_per_map", "maps_dpi", "ps_supersample", "level", "megapixels", "lights", "calibration_frames", "sensor_noise", "preset", "solver", "integrator",
          "fit_mode", "follow_fibres", "status", "wall_s", "total_s", "peak_rss_mib", "read_s", "calibration_s", "rectify_s", "alpha_s",
          "photometric_stereo_s", "integration_s", "fit_s", "write_s", "steps_skipped", "normal_mean_deg",
          "normal_median_deg", "normal_p95_deg", "albedo_de2000", "base_color_de2000", "height_rmse_mm",
          "height_rmse_pct", "height_levelled_rmse_pct", "roughness_err", "specular_err", "specular_tint_err", "sheen_err", "sheen_tint_err",
          "anisotropic_err", "metallic_err", "rerender_rel_rmse", "rerender_truth_maps_rel_rmse", "held_out_rel_rmse", "unreliable", "error"};
}

void WriteBenchCsv(const std::vector<BenchRow>& rows, const fs::path& path) {
  std::ostringstream s;
  s << Join(BenchCsvColumns(), ",") << "\n";
  for (const BenchRow& r : rows) {
    const Evaluation& e = r.evaluation;
    const bool ok = r.status == "ok";
    auto v = [&](double x, int d) { return ok ? Fixed(x, d) : std::string(); };
    // A figure only some runs have (NaN for the others): empty then.
    auto optional = [&](double x, int d) { return ok && std::isfinite(x) ? Fixed(x, d) : std::string(); };
    std::vector<std::string> cells = {
        r.c.group, r.c.scene, r.c.rig, std::to_string(r.c.size_px), std::to_string(r.c.camera_per_map), Fixed(r.c.MapsDpi(), 0),
        std::to_string(r.c.ps_supersample), r.c.level, v(r.megapixels, 4), std::to_string(r.lights_used),
        r.c.calibration_frames ? "yes" : "no", r.c.sensor_noise ? "yes" : "no", r.c.preset, r.solver_used, r.integrator_used, r.fit_mode_used,
        r.c.follow_fibres ? "yes" : "no", r.status,
        Fixed(r.wall_s, 3), v(r.total_s, 3), Fixed(r.peak_rss_mib, 1), v(r.stages.read, 3), v(r.stages.calibration, 3),
        v(r.stages.rectify, 3), v(r.stages.alpha, 3), v(r.stages.photometric_stereo, 3), v(r.stages.integration, 3),
        v(r.stages.fit, 3), v(r.stages.write, 3), Join(r.skipped, "; "), v(e.normal_mean_deg, 3),
        v(e.normal_median_deg, 3), v(e.normal_p95_deg, 3), v(e.albedo_de_mean, 3), v(e.base_color_de_mean, 3),
        v(e.height_rmse_mm, 5), v(e.height_rmse_percent, 2),
        optional(e.height_levelled_rmse_percent, 2)};
    for (int p = 0; p < 7; ++p) cells.push_back(ParameterCell(r, p));
    cells.push_back(v(e.rerender_relative_rmse, 4));
    cells.push_back(v(e.rerender_truth_maps_relative_rmse, 4));
    cells.push_back(optional(r.held_out_rmse, 4));
    cells.push_back(Join(r.unreliable, "; "));
    cells.push_back(r.error);
    for (auto& cell : cells) cell = Csv(cell);
    s << Join(cells, ",") << "\n";
  }
  WriteTextFileAtomically(path, s.str(), "a writable output folder");
}

namespace {

// The run of `capture` with `preset` and no method overridden (the baseline the methods, held-out,
// model-mismatch, camera-finer and needs-less tables compare with); null when it did not run or failed.
const BenchRow* DefaultRun(const std::vector<BenchRow>& rows, const std::string& capture, const std::string& preset) {
  for (const BenchRow& r : rows) {
    if (r.c.CaptureId() == capture && r.c.preset == preset && r.c.solver.empty() && r.c.integrator.empty() &&
        r.c.fit_mode.empty() && r.c.hold_out_lights.empty() && r.c.ps_supersample == 1 && r.status == "ok") {
      return &r;
    }
  }
  return nullptr;
}

// Every run: its times and its errors, one line each (a failed run: its error).
std::string EveryRunSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "## Every run\n\n";
  s << "| group | scene | rig | px | lights | preset | PS/integration | total s | PS s | int. s | fit s | peak MiB | normal mean / p95 deg "
       "| albedo dE | base dE | height RMSE % | roughness err | specular err | sheen err | re-render % |\n";
  s << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    const Evaluation& e = r.evaluation;
    s << "| " << r.c.group << " | " << r.c.scene << " | " << r.c.rig << (r.c.calibration_frames ? "" : " (no cal.)") << (r.c.sensor_noise ? "" : " (no noise)") << " | "
      << r.c.size_px << " | " << r.lights_used << " | " << r.c.preset << " | ";
    if (r.status != "ok") {
      s << "failed: " << r.error << " |||||||||||||\n";
      continue;
    }
    s << MethodLabel(r) << " | " << Fixed(r.total_s, 2) << " | " << Fixed(r.stages.photometric_stereo, 2) << " | "
      << Fixed(r.stages.integration, 2) << " | " << Fixed(r.stages.fit, 2) << " | " << Fixed(r.peak_rss_mib, 0) << " | "
      << Fixed(e.normal_mean_deg, 2) << " / " << Fixed(e.normal_p95_deg, 2) << " | " << Fixed(e.albedo_de_mean, 2) << " | "
      << Fixed(e.base_color_de_mean, 2) << " | " << Fixed(e.height_rmse_percent, 1) << " | " << ParameterCell(r, 0) << " | "
      << ParameterCell(r, 1) << " | " << ParameterCell(r, 3) << " | " << Fixed(100.0 * e.rerender_relative_rmse, 2) << " |\n";
  }
  return s.str();
}

// Presets: means over the matrix captures that ran with every preset, so each preset is
// averaged over the same scenes.
std::string PresetsSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  std::map<std::string, int> presets_ok;
  for (const BenchRow& r : rows) {
    if (r.c.group == "matrix" && r.status == "ok") ++presets_ok[r.c.CaptureId()];
  }
  s << "\n## Presets (mean over the matrix captures that ran every preset)\n\n| preset | runs | total s | normal mean deg | base dE | "
       "height RMSE % | re-render % |\n|---|---|---|---|---|---|---|\n";
  for (const char* preset : {"fast", "balanced", "best"}) {
    double t = 0, n_err = 0, de = 0, hr = 0, rr = 0;
    int k = 0;
    for (const BenchRow& r : rows) {
      if (r.c.group != "matrix" || r.c.preset != preset || r.status != "ok" || presets_ok[r.c.CaptureId()] < 3) continue;
      t += r.total_s;
      n_err += r.evaluation.normal_mean_deg;
      de += r.evaluation.base_color_de_mean;
      hr += r.evaluation.height_rmse_percent;
      rr += r.evaluation.rerender_relative_rmse;
      ++k;
    }
    if (k == 0) continue;
    s << "| " << preset << " | " << k << " | " << Fixed(t / k, 2) << " | " << Fixed(n_err / k, 2) << " | " << Fixed(de / k, 2)
      << " | " << Fixed(hr / k, 1) << " | " << Fixed(100.0 * rr / k, 2) << " |\n";
  }
  return s.str();
}

// Methods: each override run (solver, integrator) against the balanced run on the same capture.
std::string MethodsSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Methods on the same capture\n\n| capture | method | total s | step s | normal mean deg | height RMSE % | re-render % |\n|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "methods" || r.status != "ok" || !r.c.fit_mode.empty()) continue;
    const BenchRow* base = DefaultRun(rows, r.c.CaptureId(), "balanced");
    auto line = [&](const BenchRow& x, const std::string& label, double step_s) {
      s << "| " << x.c.CaptureId() << " | " << label << " | " << Fixed(x.total_s, 2) << " | " << Fixed(step_s, 2) << " | "
        << Fixed(x.evaluation.normal_mean_deg, 2) << " | " << Fixed(x.evaluation.height_rmse_percent, 1) << " | "
        << Fixed(100.0 * x.evaluation.rerender_relative_rmse, 2) << " |\n";
    };
    const bool ps = !r.c.solver.empty();
    if (base) line(*base, (ps ? "PS " + base->solver_used : "integration " + base->integrator_used) + " (balanced)",
                   ps ? base->stages.photometric_stereo : base->stages.integration);
    line(r, ps ? "PS " + r.solver_used : "integration " + r.integrator_used, ps ? r.stages.photometric_stereo : r.stages.integration);
  }
  return s.str();
}

// Fit mode: --fit-mode clusters against the balanced run (per-pixel) on the same capture.
std::string FitModeSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n### Fit: clusters vs per-pixel (same capture, preset balanced)\n\n| capture | fit mode | total s | fit s | "
       "roughness err | specular err | anisotropic err | re-render % | flagged unreliable |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "methods" || r.status != "ok" || r.c.fit_mode.empty()) continue;
    const BenchRow* base = DefaultRun(rows, r.c.CaptureId(), "balanced");
    auto line = [&](const BenchRow& x) {
      s << "| " << x.c.CaptureId() << " | " << x.fit_mode_used << " | " << Fixed(x.total_s, 2) << " | "
        << Fixed(x.stages.fit, 2) << " | " << ParameterCell(x, 0) << " | " << ParameterCell(x, 1) << " | "
        << ParameterCell(x, 5) << " | " << Fixed(100.0 * x.evaluation.rerender_relative_rmse, 2) << " | "
        << Join(x.unreliable, "; ") << " |\n";
    };
    if (base) line(*base);
    line(r);
  }
  return s.str();
}

// Held out: the held-out photographs' error against the truth-based re-render of the same run
// and of the run with every light.
std::string HeldOutSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Held-out photographs (lights left out of the fit)\n\n| capture | maps dpi | preset | held-out lights | total s | "
       "held-out photographs re-render % | truth re-render % (this run) | truth re-render % (every light) |\n"
       "|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "held-out" || r.status != "ok") continue;
    const BenchRow* all = r.c.camera_per_map == 1 ? DefaultRun(rows, r.c.CaptureId(), r.c.preset) : nullptr;
    s << "| " << r.c.CaptureId() << " | " << Fixed(r.c.MapsDpi(), 0) << " | " << r.c.preset << " | " << r.c.hold_out_lights << " | " << Fixed(r.total_s, 2)
      << " | " << Fixed(100.0 * r.held_out_rmse, 2) << " | " << Fixed(100.0 * r.evaluation.rerender_relative_rmse, 2)
      << " | " << (all ? Fixed(100.0 * all->evaluation.rerender_relative_rmse, 2) : std::string("-")) << " |\n";
  }
  return s.str();
}

// Model mismatch, against the Principled velvet of the same rig and preset.
std::string ModelMismatchSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Model mismatch (velvet rendered with Charlie sheen, fitted with the Principled BRDF)\n\n| capture | "
       "preset | normal mean deg | base dE | roughness err | specular err | sheen err | re-render % | truth's own maps "
       "re-render % | flagged unreliable | Principled velvet: roughness err | specular err | sheen err | re-render % |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "model-mismatch" || r.status != "ok") continue;
    BenchCase principled = r.c;
    principled.scene = "velvet";
    const BenchRow* same = DefaultRun(rows, principled.CaptureId(), r.c.preset);
    const Evaluation& e = r.evaluation;
    s << "| " << r.c.CaptureId() << " | " << r.c.preset << " | " << Fixed(e.normal_mean_deg, 2) << " | "
      << Fixed(e.base_color_de_mean, 2) << " | " << ParameterCell(r, 0) << " | " << ParameterCell(r, 1) << " | "
      << ParameterCell(r, 3) << " | " << Fixed(100.0 * e.rerender_relative_rmse, 2) << " | "
      << Fixed(100.0 * e.rerender_truth_maps_relative_rmse, 2) << " | " << Join(r.unreliable, "; ") << " | ";
    if (same) {
      s << ParameterCell(*same, 0) << " | " << ParameterCell(*same, 1) << " | " << ParameterCell(*same, 3) << " | "
        << Fixed(100.0 * same->evaluation.rerender_relative_rmse, 2) << " |\n";
    } else {
      s << "- | - | - | - |\n";
    }
  }
  return s.str();
}

// Camera finer than the maps, against the 1x matrix run of the same scene and preset.
std::string CameraFinerSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Camera finer than the maps (footprint pre-filter)\n\n| capture | camera px per map px | photometric stereo grid | "
       "level | preset | total s | normal mean / p95 deg | albedo dE | height % | re-render % | truth's own maps re-render % | "
       "at 1x: normal mean / p95 deg | height % | re-render % |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "camera-finer" || r.status != "ok") continue;
    BenchCase one = r.c;
    one.camera_per_map = 1;
    const BenchRow* at_1x = DefaultRun(rows, one.CaptureId(), r.c.preset);
    const Evaluation& e = r.evaluation;
    s << "| " << r.c.CaptureId() << " | " << r.c.camera_per_map << " | "
      << (r.c.ps_supersample == 1 ? "maps'" : "camera's (--ps-supersample 0)") << " | " << r.c.level << " | " << r.c.preset << " | "
      << Fixed(r.total_s, 2) << " | "
      << Fixed(e.normal_mean_deg, 2) << " / " << Fixed(e.normal_p95_deg, 2) << " | " << Fixed(e.albedo_de_mean, 2) << " | "
      << Fixed(e.height_rmse_percent, 1) << " | " << Fixed(100.0 * e.rerender_relative_rmse, 2) << " | "
      << Fixed(100.0 * e.rerender_truth_maps_relative_rmse, 2) << " | ";
    if (at_1x) {
      const Evaluation& a = at_1x->evaluation;
      s << Fixed(a.normal_mean_deg, 2) << " / " << Fixed(a.normal_p95_deg, 2) << " | " << Fixed(a.height_rmse_percent, 1) << " | "
        << Fixed(100.0 * a.rerender_relative_rmse, 2) << " |\n";
    } else {
      s << "- | - | - |\n";
    }
  }
  return s.str();
}

// Fibre directions: each --follow-fibres run against the run of the same capture, preset and grid
// without it (the camera-finer group's).
std::string FibresSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Fibre directions (`--follow-fibres`) against one turn per cluster\n\n| capture | preset | follow fibres | "
       "total s | fit s | normal mean deg | roughness err | specular err | anisotropic err | re-render % |\n"
       "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.c.group != "fibres" || r.status != "ok") continue;
    // The same case but the option: the same run id without its "_fibres".
    BenchCase same = r.c;
    same.follow_fibres = false;
    const std::string id = same.RunId();
    const auto it =
        std::find_if(rows.begin(), rows.end(), [&](const BenchRow& x) { return x.status == "ok" && x.c.RunId() == id; });
    const BenchRow* without = it != rows.end() ? &*it : nullptr;
    auto line = [&](const BenchRow& x) {
      s << "| " << x.c.CaptureId() << " | " << x.c.preset << " | " << (x.c.follow_fibres ? "yes" : "no") << " | "
        << Fixed(x.total_s, 2) << " | " << Fixed(x.stages.fit, 2) << " | " << Fixed(x.evaluation.normal_mean_deg, 3) << " | "
        << ParameterCell(x, 0) << " | " << ParameterCell(x, 1) << " | " << ParameterCell(x, 5) << " | "
        << Fixed(100.0 * x.evaluation.rerender_relative_rmse, 2) << " |\n";
    };
    if (without) line(*without);
    line(r);
  }
  return s.str();
}

// Needs less: steps skipped and the time they save.
std::string NeedsLessSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Scenes that need less: steps skipped and time saved\n\n| capture | preset | steps skipped | calibration s | total s | "
       "compared with | its calibration s | its total s | saved s |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (r.status != "ok") continue;
    // `r` needs less than `full`: no calibration frames, distant instead of near lights, or the
    // top camera alone instead of top + oblique.
    const BenchRow* full = nullptr;
    if (r.c.group == "needs-less") {
      BenchCase with = r.c;
      with.calibration_frames = true;
      full = DefaultRun(rows, with.CaptureId(), r.c.preset);
    } else if (r.c.group == "matrix" && r.c.preset == "balanced" && r.c.rig == "distant") {
      BenchCase near = r.c;
      near.rig = "near";
      full = DefaultRun(rows, near.CaptureId(), r.c.preset);
    } else if (r.c.group == "matrix" && r.c.rig == "near") {
      BenchCase oblique = r.c;
      oblique.rig = "oblique";
      full = DefaultRun(rows, oblique.CaptureId(), r.c.preset);
    }
    if (!full) continue;
    s << "| " << r.c.CaptureId() << " | " << r.c.preset << " | " << Join(r.skipped, "; ") << " | " << Fixed(r.stages.calibration, 2) << " | "
      << Fixed(r.total_s, 2) << " | " << full->c.CaptureId() << " | " << Fixed(full->stages.calibration, 2) << " | "
      << Fixed(full->total_s, 2) << " | " << Fixed(full->total_s - r.total_s, 2) << " |\n";
  }
  return s.str();
}

}  // namespace

void WriteBenchMarkdown(const std::vector<BenchRow>& rows, const BenchOptions& options, const fs::path& path) {
  std::ostringstream s;
  s << "# u3mscan bench" << (options.quick ? " --quick" : "") << "\n\n";
  s << UtcDate() << ", " << Machine() << ". Times in seconds (the run's report.json), peak RSS of the child `u3mscan "
    << "process` in MiB; errors against the synthetic truth (docs/bench.md).\n\n";
  s << EveryRunSection(rows) << IssueTargetsSection(rows) << PresetsSection(rows) << MethodsSection(rows)
    << FitModeSection(rows) << HeldOutSection(rows) << ModelMismatchSection(rows) << CameraFinerSection(rows)
    << FibresSection(rows) << NeedsLessSection(rows);
  s << "\nPlots: `error_vs_time.svg`, `rerender_vs_time.svg`, `time_vs_megapixels.svg`, `time_vs_lights.svg`.\n";
  WriteTextFileAtomically(path, s.str(), "a writable output folder");
}

void WriteBenchPlots(const std::vector<BenchRow>& rows, const fs::path& out_dir) {
  auto by_preset = [&](auto x_of, auto y_of, auto keep) {
    std::vector<PlotSeries> series;
    for (const char* preset : {"fast", "balanced", "best"}) {
      PlotSeries s;
      s.name = preset;
      for (const BenchRow& r : rows) {
        if (r.status != "ok" || r.c.preset != preset || !r.c.solver.empty() || !r.c.integrator.empty() || !keep(r)) continue;
        s.points.push_back({x_of(r), y_of(r), r.c.CaptureId()});
      }
      if (!s.points.empty()) series.push_back(std::move(s));
    }
    return series;
  };
  auto matrix = [](const BenchRow& r) { return r.c.group == "matrix" || r.c.group == "needs-less"; };
  PlotSpec error_spec{"Normal error against run time (one point per preset and scene)", "run time (s)", "mean normal error (deg)"};
  WriteScatterPlotSvg(error_spec,
                      by_preset([](const BenchRow& r) { return r.total_s; },
                                [](const BenchRow& r) { return r.evaluation.normal_mean_deg; }, matrix),
                      out_dir / "error_vs_time.svg");
  PlotSpec rerender_spec{"Re-render error (held-out lights) against run time", "run time (s)", "relative RMSE (%)"};
  WriteScatterPlotSvg(rerender_spec,
                      by_preset([](const BenchRow& r) { return r.total_s; },
                                [](const BenchRow& r) { return 100.0 * r.evaluation.rerender_relative_rmse; }, matrix),
                      out_dir / "rerender_vs_time.svg");
  auto scaling = [](const BenchRow& r) {
    return r.c.scene == "plain" && r.c.rig == "distant" && r.c.calibration_frames && (r.c.group == "matrix" || r.c.group == "size" || r.c.group == "lights");
  };
  auto connected = [](std::vector<PlotSeries> s) {
    for (auto& x : s) x.connect = true;
    return s;
  };
  PlotSpec mp_spec{"Run time against megapixels (plain, distant rig)", "finished map megapixels", "run time (s)"};
  WriteScatterPlotSvg(mp_spec,
                      connected(by_preset([](const BenchRow& r) { return r.megapixels; }, [](const BenchRow& r) { return r.total_s; },
                                          [&](const BenchRow& r) { return scaling(r) && r.c.lights == 0; })),
                      out_dir / "time_vs_megapixels.svg");
  PlotSpec lights_spec{"Run time against number of lights (plain, distant rig)", "lights", "run time (s)"};
  WriteScatterPlotSvg(lights_spec,
                      connected(by_preset([](const BenchRow& r) { return static_cast<double>(r.lights_used); },
                                          [](const BenchRow& r) { return r.total_s; },
                                          [&](const BenchRow& r) { return scaling(r) && r.c.group != "size"; })),
                      out_dir / "time_vs_lights.svg");
}

std::vector<BenchRow> RunBench(const BenchOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw InputError("bench options", "", why);
  if (!fs::exists(options.executable)) throw InputError(options.executable.string(), "", "the u3mscan executable");
  std::error_code ec;
  fs::create_directories(options.out_dir, ec);
  if (ec) throw InputError(options.out_dir.string(), "", "a folder that can be created: " + ec.message());
  std::vector<BenchCase> cases = BenchMatrix(options);
  if (!options.only.empty()) {
    std::erase_if(cases, [&](const BenchCase& c) {
      return std::none_of(options.only.begin(), options.only.end(),
                          [&](const std::string& part) { return c.RunId().find(part) != std::string::npos; });
    });
    if (cases.empty()) throw InputError("--only", "", "a part of at least one case name, e.g. plain_distant_48_fast");
  }
  std::vector<BenchRow> rows;
  const double start = SteadySeconds();
  for (std::size_t k = 0; k < cases.size(); ++k) {
    BenchRow row;
    try {
      row = RunCase(cases[k], options);
    } catch (const std::exception& e) {  // a capture that cannot be rendered: report it, go on
      row.c = cases[k];
      row.status = "failed";
      row.error = e.what();
    }
    LogInfo() << "bench " << (k + 1) << "/" << cases.size() << " " << cases[k].RunId() << ": " << row.status << ", "
              << Fixed(row.wall_s, 2) << " s"
              << (row.status == "ok" ? ", normal " + Fixed(row.evaluation.normal_mean_deg, 2) + " deg" : " " + row.error);
    rows.push_back(std::move(row));
    // After every case (atomic rewrites), so a long run can be read while it goes on and an
    // interrupted one keeps what it measured.
    WriteBenchCsv(rows, options.out_dir / "bench.csv");
    WriteBenchMarkdown(rows, options, options.out_dir / "bench.md");
    WriteBenchPlots(rows, options.out_dir);
  }
  if (!options.keep_work) fs::remove_all(options.out_dir / "work", ec);
  LogInfo() << "bench: " << rows.size() << " runs in "
            << Fixed(SteadySeconds() - start, 1) << " s, written to "
            << options.out_dir.string();
  return rows;
}

}  // namespace u3mscan::bench
