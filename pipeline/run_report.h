#pragma once
// RunReport: what one run of the pipeline did, for people (report.html) and machines (report.json).
// Every figure in it was measured in that run; nothing is filled in by hand.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.h"

namespace u3mscan {

// One pipeline step: it either ran (with its run time) or was skipped, always with a reason so the
// operator can see why (e.g. "no chart frames: colour correction skipped").
struct StepRecord {
  std::string name;
  bool ran = false;
  std::string reason;
  double seconds = 0.0;
};

// Where a U3M parameter's value comes from.
enum class ParameterSource {
  kMeasured,     // fitted from the capture, written as a texture (non-uniform map)
  kConstant,     // measured, uniform within noise: written as a constant, no texture
  kDefault,      // the capture cannot tell (not measured): U3M default, no texture
  kNotApplicable // the material does not have it (e.g. no holes: no alpha map)
};
const char* ParameterSourceName(ParameterSource source);

struct ParameterRecord {
  std::string name;      // U3M key, e.g. "roughness"
  ParameterSource source = ParameterSource::kDefault;
  std::string reason;    // why, in words an operator understands
  double value = 0.0;    // the constant written (mean of the map when there is one)
  double uncertainty = 0.0;  // one standard deviation where the fit gives one, else 0
  // Empty: nothing says the value is off. Else the value is written but flagged unreliable, and this
  // says which of the run's own evidence flags it (docs/fitting.md, "Reliable or not").
  std::string unreliable_reason;
  bool reliable() const { return unreliable_reason.empty(); }
};

// An image shown in the report as a thumbnail.
struct ReportImage {
  std::string label;
  std::string group;     // "input", "map", "quality"
  Image image;           // linear values
  bool colour = false;   // true: linear RGB shown through sRGB; false: data, shown min..max
};

struct RunReport {
  std::string capture_name;
  std::string capture_path;
  std::string output_path;
  std::string status = "ok";  // "ok" or "failed"
  std::string error;          // the message when failed
  std::string started_utc;
  std::string preset;
  nlohmann::json options = nlohmann::json::object();
  std::vector<StepRecord> steps;
  std::vector<ParameterRecord> parameters;
  nlohmann::json calibration = nlohmann::json::object();
  nlohmann::json quality = nlohmann::json::object();
  std::vector<std::string> warnings;
  std::vector<ReportImage> images;
  double total_seconds = 0.0;
  double peak_memory_mib = 0.0;
};

// The first step of that name, or nullptr.
const StepRecord* FindStep(const RunReport& report, const std::string& name);

nlohmann::json RunReportToJson(const RunReport& report);

// Writes a self-contained HTML page (thumbnails embedded as base64 PNG, no network, no scripts).
// Atomic: temporary file, then rename.
void WriteReportHtml(const RunReport& report, const std::filesystem::path& path);
// Writes report.json atomically.
void WriteReportJson(const RunReport& report, const std::filesystem::path& path);

}  // namespace u3mscan
