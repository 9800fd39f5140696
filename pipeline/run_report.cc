#include "pipeline/run_report.h"


#include "core/text_file.h"

namespace u3mscan {

const char* ParameterSourceName(ParameterSource source) {
  switch (source) {
    case ParameterSource::kMeasured: return "measured";
    case ParameterSource::kConstant: return "measured (uniform: constant)";
    case ParameterSource::kDefault: return "not measured (U3M default)";
    case ParameterSource::kNotApplicable: return "not applicable";
  }
  return "unknown";
}

const StepRecord* FindStep(const RunReport& report, const std::string& name) {
  for (const StepRecord& step : report.steps) {
    if (step.name == name) return &step;
  }
  return nullptr;
}

nlohmann::json RunReportToJson(const RunReport& report) {
  nlohmann::json j;
  j["capture"] = {{"name", report.capture_name}, {"path", report.capture_path}};
  j["output"] = report.output_path;
  j["status"] = report.status;
  if (!report.error.empty()) j["error"] = report.error;
  j["started_utc"] = report.started_utc;
  j["preset"] = report.preset;
  j["options"] = report.options;
  j["steps"] = nlohmann::json::array();
  for (const auto& step : report.steps) {
    j["steps"].push_back({{"name", step.name}, {"ran", step.ran}, {"reason", step.reason}, {"seconds", step.seconds}});
  }
  j["parameters"] = nlohmann::json::array();
  for (const auto& p : report.parameters) {
    nlohmann::json record = {{"name", p.name},
                             {"source", ParameterSourceName(p.source)},
                             {"reason", p.reason},
                             {"value", p.value},
                             {"uncertainty", p.uncertainty},
                             {"reliable", p.reliable()}};
    if (!p.reliable()) record["unreliable_reason"] = p.unreliable_reason;
    j["parameters"].push_back(std::move(record));
  }
  j["calibration"] = report.calibration;
  j["quality"] = report.quality;
  j["warnings"] = report.warnings;
  j["total_seconds"] = report.total_seconds;
  j["peak_memory_mib"] = report.peak_memory_mib;
  return j;
}

void WriteReportJson(const RunReport& report, const std::filesystem::path& path) {
  WriteTextFileAtomically(path, RunReportToJson(report).dump(2) + "\n", "a writable location for the report");
}

}  // namespace u3mscan
