#include "cli/stage_outputs.h"

#include <fstream>
#include <iomanip>
#include <iostream>
#include <random>
#include <system_error>

#include "core/error.h"
#include "u3m/image_io.h"

namespace u3mscan::cli {
namespace fs = std::filesystem;

void WriteStageOutputs(const fs::path& out_dir, const std::vector<std::pair<std::string, Image>>& maps,
                       const std::vector<std::pair<std::string, std::string>>& extra_files) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw InputError(out_dir.string(), "", "a folder that can be created: " + ec.message());
  const fs::path staging = out_dir / (".maps-partial-" + std::to_string(std::random_device{}()));
  try {
    fs::create_directories(staging);
    ImageWriteOptions exr;
    exr.format = SampleFormat::kFloat32;
    for (const auto& [name, image] : maps) {
      if (!image.empty()) WriteImageFile(image, staging / name, exr);
    }
    for (const auto& [name, text] : extra_files) {
      std::ofstream out(staging / name, std::ios::binary);
      out << text;
      if (!out) throw InputError((out_dir / name).string(), "", "a writable file");
    }
    fs::remove_all(out_dir / "maps", ec);
    fs::create_directories(out_dir / "maps");
    for (const auto& entry : fs::directory_iterator(staging)) {
      const bool is_map = entry.path().extension() == ".exr";
      fs::rename(entry.path(), (is_map ? out_dir / "maps" : out_dir) / entry.path().filename());
    }
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  fs::remove_all(staging, ec);
}

void PrintSteps(const RunReport& report) {
  for (const StepRecord& step : report.steps) {
    std::cout << "  " << std::left << std::setw(34) << step.name << " ";
    if (step.ran) std::cout << std::right << std::setw(8) << std::fixed << std::setprecision(2) << step.seconds << " s";
    else std::cout << std::right << std::setw(10) << "skipped";
    if (!step.reason.empty()) std::cout << "  " << step.reason;
    std::cout << "\n";
  }
}

}  // namespace u3mscan::cli
