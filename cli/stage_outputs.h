#pragma once
// Shared by the `reconstruct` and `fit` commands: run the pipeline's stages up to a point on one
// capture and write float EXR maps into DIR/maps/ (staged in a hidden folder, then renamed, so a
// failed run leaves no half-written maps).

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "core/image.h"
#include "pipeline/run_report.h"

namespace u3mscan::cli {

// Writes each (file name, image) as float EXR into out_dir/maps (replacing an earlier maps/), and
// `extra_files` (name, text) into out_dir. Atomic per folder.
void WriteStageOutputs(const std::filesystem::path& out_dir, const std::vector<std::pair<std::string, Image>>& maps,
                       const std::vector<std::pair<std::string, std::string>>& extra_files);

// One line per step: name, run time or "skipped", and why.
void PrintSteps(const RunReport& report);

}  // namespace u3mscan::cli
