#pragma once
// RunBench: error against run time over a matrix of synthetic captures (`u3mscan bench`,
// docs/bench.md).
//
// For each case: render a synthetic capture with truth (datasets_synthetic scenes and rigs),
// run `u3mscan process --debug-maps` on it in a CHILD process (so run time and peak memory are
// that run's alone; peak RSS from wait4 and the run's report.json), read the run's report.json
// (each stage's seconds, the steps skipped and why) and evaluate the output against the truth
// (bench/evaluate.h). Writes bench.csv, bench.md and the SVG plots into the output folder,
// rewritten after every case.
//
// Matrix: every fabric preset of the synthetic scanner x {distant, near} rigs x every preset at the base size; plus, on one
// scene, the method comparisons (ls vs robust photometric stereo, dct vs robust integration,
// clusters vs per-pixel fitting), the "needs less" pairs (no calibration
// frames, no oblique camera vs oblique), sizes for the megapixel axis, light subsets for the
// lights axis, held-out lights, and cameras finer than the maps. --quick shrinks every axis.

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "bench/evaluate.h"

namespace u3mscan::bench {

struct BenchCase {
  std::string scene;
  std::string rig;            // distant | near | oblique (datasets_synthetic/rig.h)
  int size_px = 64;           // camera width = height
  int lights = 0;             // 0: every light of the rig; else this many, spread over the rig's lights
  bool calibration_frames = true;  // false: no dark/flat/board/sphere/chart/backlight frames
  std::string preset = "balanced";
  std::string solver;         // "" = the preset's
  std::string integrator;     // "" = the preset's
  std::string group;          // why the case is in the matrix: matrix | methods | needs-less | size | lights
  std::string fit_mode;       // "" = the preset's; clusters | per-pixel (u3mscan process --fit-mode)
  // "" = none; light ids, comma-separated (u3mscan process --hold-out-lights): group "held-out"
  std::string hold_out_lights;
  // Camera pixels per finished-map pixel along each axis: 1 = the camera at the maps' 300 dpi; 2 =
  // a camera at 600 dpi (size_px * 2 pixels, the same sample) processed with --dpi 300: group
  // "camera-finer".
  int camera_per_map = 1;
  // With camera_per_map > 1: the maps at the camera's dpi (300 * camera_per_map), not the
  // matrix's 300 dpi: a material that resolves what the camera resolves (group "held-out").
  bool maps_at_camera_dpi = false;
  // false: the capture exposed without sensor noise (`u3mscan synth --no-noise`): what is left of
  // a held-out error is the material's own (group "held-out").
  bool sensor_noise = true;
  // u3mscan process --ps-supersample: 1 = photometric stereo on the maps' grid, 0 = as fine as
  // the camera resolves (pipeline/supersampled_reconstruction.h); group "camera-finer".
  int ps_supersample = 1;
  // u3mscan process --level: none | plane (the default) | quadratic (docs/process.md, "Levelling");
  // group "camera-finer" runs plain with quadratic too.
  std::string level = "plane";
  // u3mscan process --follow-fibres: the anisotropic stretch turned per pixel along the fibres the
  // normals show (docs/fitting.md, "Fibre directions from the relief"); group "fibres".
  bool follow_fibres = false;
  double MapsDpi() const;         // the finished maps' dpi: 300, or the camera's with maps_at_camera_dpi
  std::string CaptureId() const;  // the capture a case runs on (shared by presets and methods)
  std::string RunId() const;
};

struct StageSeconds {
  double read = 0, calibration = 0, rectify = 0, alpha = 0, photometric_stereo = 0, integration = 0, fit = 0, write = 0;
};

struct BenchRow {
  BenchCase c;
  int lights_used = 0;         // lights in the capture
  double megapixels = 0;       // finished map pixels / 1e6
  std::string status = "ok";   // ok | failed (exit code and message in `error`)
  std::string error;
  std::string solver_used, integrator_used, fit_mode_used;  // from report.json /options
  std::vector<std::string> unreliable;  // parameters report.json flags unreliable ("front/specular_value")
  double wall_s = 0;           // child process, fork to exit
  double total_s = 0;          // report.json /total_seconds
  double peak_rss_mib = 0;     // child's max RSS (wait4)
  StageSeconds stages;
  // Re-render error against the photographs of the held-out lights (report.json
  // /quality/front/held_out_lights/relative_rmse); NaN when the case holds none out.
  double held_out_rmse = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::string> skipped;  // names of steps that did not run
  Evaluation evaluation;
};

struct BenchOptions {
  bool quick = false;
  std::filesystem::path out_dir = "bench-out";
  std::filesystem::path executable;  // the u3mscan binary for the child runs (required)
  int threads = 0;                   // --threads of each child (0: all cores)
  bool keep_work = false;            // keep captures and run outputs under out_dir/work
  // Run only the cases whose RunId() contains one of these substrings (empty: every case), e.g.
  // "knit_distant_128_balanced" to rerun one case of the full matrix.
  std::vector<std::string> only;
  std::uint64_t seed = 1;
  bool Check(std::string* why) const;
};

// The fabric presets of datasets_synthetic/scene.h the matrix covers (not the extreme ones).
std::vector<std::string> BenchFabricScenes();
// The cases RunBench runs for these options, in order.
std::vector<BenchCase> BenchMatrix(const BenchOptions& options);

// Runs every case; a failed case is a row with status "failed", the others still run. Writes
// bench.csv, bench.md and the plots (error_vs_time.svg, rerender_vs_time.svg, time_vs_megapixels.svg,
// time_vs_lights.svg). Throws InputError when out_dir or the executable cannot be used.
std::vector<BenchRow> RunBench(const BenchOptions& options);

// The files RunBench writes, from rows (exposed for tests).
void WriteBenchCsv(const std::vector<BenchRow>& rows, const std::filesystem::path& path);
void WriteBenchMarkdown(const std::vector<BenchRow>& rows, const BenchOptions& options, const std::filesystem::path& path);
void WriteBenchPlots(const std::vector<BenchRow>& rows, const std::filesystem::path& out_dir);
// The CSV header columns, in order.
std::vector<std::string> BenchCsvColumns();

}  // namespace u3mscan::bench
