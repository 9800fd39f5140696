#pragma once
// Evaluate: the errors of a processed synthetic capture against its ground truth (the synthetic
// round-trip check; `u3mscan evaluate OUTPUT TRUTH`, and every row of `u3mscan bench`).
//
// Inputs: OUTPUT is the folder `u3mscan process --debug-maps` wrote (report.json, maps/*.exr);
// TRUTH is the synthetic capture's truth/ folder (truth.json + maps, bench/truth_maps.h).
// The processed maps lie on the calibrated metric grid (report.json /calibration/grid: pitch_mm,
// region_mm), the truth maps on the scene's grid (truth.json /rig/sample_rect_mm); both in world mm.
// The truth is resampled bilinearly at each output pixel centre, or averaged over each output
// pixel's footprint when the output is coarser (bench/truth_footprint.h). Only pixels whose truth
// neighbours or footprint are all fabric (alpha >= 0.5; no holes, no table) are compared.
//
// Definitions and units are in docs/bench.md.

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace u3mscan::bench {

struct EvaluateOptions {
  std::string side = "front";  // front | back (maps/<side>_*.exr for the back)
  // Held-out lights: directional, view straight above; at most this many, none within
  // min_separation_deg of a capture light.
  int max_held_out_lights = 8;
  double min_separation_deg = 10.0;
  bool Check(std::string* why) const;
};

// One fitted parameter against its truth. "Not measured" parameters (the capture does not
// constrain them: U3M default, no texture) carry no error: measured = false and the error fields NaN.
struct ParameterError {
  std::string name;        // fitting name: roughness, specular, specular_tint, sheen, sheen_tint, anisotropic, metallic
  std::string u3m_key;     // roughness, specular_value, ...
  std::string source;      // "map" (per-pixel texture), "constant" (U3M constant), "not measured", "absent"
  bool measured = false;
  bool reliable = true;          // false: the run's report flags the value unreliable (docs/fitting.md)
  double truth_mean = 0.0;       // over the compared pixels
  double estimate_mean = 0.0;    // the material's value (map mean or constant)
  double mean_abs_error = 0.0;   // mean over compared pixels of |estimate - truth| (NaN when not measured)
  double bias = 0.0;             // estimate_mean - truth_mean (NaN when not measured)
};

struct Evaluation {
  std::string scene;  // truth.json /scene (the synthetic scene's name; "" when absent)
  std::string side;
  int width = 0, height = 0;       // output grid
  long long pixels_compared = 0;
  // Normal angular error, degrees.
  double normal_mean_deg = 0, normal_median_deg = 0, normal_p95_deg = 0;
  // CIEDE2000 of the photometric-stereo albedo (maps/albedo.exr) and of the written base colour
  // (maps/base_color.exr, else the albedo) against the truth base colour.
  double albedo_de_mean = 0, albedo_de_median = 0, albedo_de_p95 = 0;
  double base_color_de_mean = 0, base_color_de_median = 0, base_color_de_p95 = 0;
  // Height RMSE after removing the mean offset, mm and % of the truth's height range.
  double height_rmse_mm = 0, height_range_mm = 0, height_rmse_percent = 0;
  // The run's levelling (report.json /options/levelling; "none" when absent) and, when it is not
  // none, the height RMSE against the truth levelled the same way (reconstruction/relief_levelling.h
  // over the compared pixels), mm and % of the same (unlevelled) range: a tilt or bowl of the
  // truth's own, which a levelled run takes out by design, is then not counted as error. NaN
  // otherwise.
  std::string height_levelling = "none";
  double height_levelled_rmse_mm = std::numeric_limits<double>::quiet_NaN();
  double height_levelled_rmse_percent = std::numeric_limits<double>::quiet_NaN();
  std::vector<ParameterError> parameters;  // fitting::FitParameter order
  // Re-render error under held-out lights: sqrt(sum (fit - truth)^2 / sum truth^2) over compared
  // pixels, RGB and lights (no cast shadows), view straight above; the fit rendered with
  // core/principled_brdf.h in the fitter's frame (+x projected), the truth with the model its scene
  // was rendered with (truth.json /reflectance_model: the Principled BRDF, or the scanner's Charlie
  // sheen under model mismatch) in the scene's fibre frame.
  int held_out_lights = 0;
  std::string truth_reflectance_model = "principled";  // truth.json /reflectance_model: how the truth was rendered
  double rerender_relative_rmse = 0;
  // The same figure for the truth's own maps on the output grid as a Principled material (each
  // pixel's footprint-mean parameters and unit normal, rendered as one pixel): what a material
  // holding the truth's means reaches. 0 when the output is not coarser than the truth and the
  // truth is Principled (the truth is then interpolated, and rendered as such); on a coarser
  // output a pixel's facets render otherwise than their mean, and under model mismatch the
  // Principled lobes otherwise than the fabric's. Not a lower bound: a material fitted to the
  // pixel's appearance can come closer (plain at 3x: 5.66 against 7.35 %, docs/fitting.md "The
  // truth's own maps under held-out lights").
  double rerender_truth_maps_relative_rmse = 0;
};

// Throws InputError naming the file and field when OUTPUT or TRUTH cannot be used.
Evaluation Evaluate(const std::filesystem::path& output_dir, const std::filesystem::path& truth_dir,
                    const EvaluateOptions& options = {});

// The figures of parameter `name` (ParameterError::name: roughness, specular, ...); throws
// std::out_of_range when the evaluation has none by that name.
const ParameterError& FindParameter(const Evaluation& evaluation, const std::string& name);

nlohmann::json EvaluationToJson(const Evaluation& evaluation);
// Every figure, one per line, for people.
std::string EvaluationToText(const Evaluation& evaluation);

}  // namespace u3mscan::bench
