#pragma once
// Material writer: the finished maps of a scan -> a complete U3M (.u3m + textures/, or one .u3ma).
//
// Rules (docs/u3m-conventions.md, issue "process"): every map is written only when it is not
// uniform, otherwise as a constant; parameters the capture did not measure stay at their U3M
// defaults with no texture; constants always equal the mean of the final (quantised) texture; the
// normal map is tangent space, OpenGL convention; displacement is a 16-bit map of 0..1 whose scale
// in mm is recorded in our custom section; the schema version is the lowest that holds the content.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.h"
#include "pipeline/run_report.h"
#include "u3m/material_io.h"

namespace u3mscan {

// One scalar parameter of one side, as the fit decided it.
struct ScalarMapChoice {
  std::string u3m_key;       // "roughness", "specular_value", "sheen_tint", ...
  ParameterSource source = ParameterSource::kDefault;
  double value = 0.0;        // constant (default / uniform) or the fitted map's mean
  Image map;                 // kMeasured only: 1 channel on the side's grid, value / texture_factor
  double texture_factor = 1.0;  // the U3M texture's factor: map * factor is the value (rotation: 180 deg)
  std::string reason;
  std::string unreliable_reason;  // non-empty: written, but flagged unreliable (ParameterRecord)
};

// The finished maps of one side, on the metric grid (every Image's pitch_mm is the grid pitch).
struct SideMaps {
  std::string side = "front";   // "front" or "back"
  Image base_color;              // 3 channels, linear RGB 0..1
  Image normal;                  // 3 channels, unit, world frame (x right, y up, z out of the fabric)
  std::string normal_source = "photometric stereo";  // the report's reason for a normal texture
  Image height_mm;               // 1 channel, mm, +z toward a camera above the sample
  Image alpha;                   // 1 channel 0..1; empty: the sample has no holes
  std::string height_unreliable_reason;  // non-empty: displacement written, flagged unreliable
  std::vector<ScalarMapChoice> scalars;
};

struct ScanMaterialRequest {
  std::string name;              // material name; file names use SafeName(name)
  std::string file_stem;         // <stem>.u3m / <stem>.u3ma
  std::string description;
  std::optional<std::string> id;            // lowercase v4 UUID; unset = new random
  std::optional<std::int64_t> created_ms;   // UTC; unset = now
  std::string schema = "auto";   // "auto", "1.0", "1.1"
  bool package = false;          // one .u3ma instead of .u3m + textures/
  std::optional<double> thickness_mm;       // -> 1.1 physics (with weight)
  std::optional<double> weight_gsm;
  std::string vendor_key = "u3mscan";       // custom section key: the scanner vendor's name
  nlohmann::json custom_section = nlohmann::json::object();  // our own section's content
  std::vector<SideMaps> sides;   // front first; back when the capture has one
};

// Uniformity thresholds below which a map is written as a constant, in the map's own units.
struct UniformityThresholds {
  double base_color_std = 0.002;     // linear RGB, about one 8-bit sRGB step in the mid-tones
  double normal_angle_deg = 0.5;     // every normal within this of the mean normal
  double height_range_mm = 0.001;    // 1 micrometre
};

struct ScanMaterialResult {
  std::filesystem::path material_path;   // the .u3m or .u3ma written
  SchemaVersion version = SchemaVersion::k1_0;
  std::vector<std::string> files;        // texture files written, relative to the material
  std::vector<ParameterRecord> parameters;  // per side-prefixed key: where its value came from
  double displacement_mm_per_unit = 0.0;    // 0 when displacement is a constant
  double displacement_zero_mm = 0.0;        // height (mm) of displacement value 0
};

// Writes the material into `out_dir` (created if needed). Atomic through SaveMaterial: a failure
// leaves no material behind. `overwrite` replaces an existing material of the same name.
ScanMaterialResult WriteScanMaterial(const ScanMaterialRequest& request, const std::filesystem::path& out_dir,
                                      bool overwrite, const UniformityThresholds& thresholds = {});

// A shaded preview of a side: base colour lit by a light from the upper left through the normals.
Image RenderPreview(const SideMaps& side);

}  // namespace u3mscan
