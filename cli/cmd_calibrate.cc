// `u3mscan calibrate CAPTURE -o DIR`: runs the calibration steps the capture calls for and writes
// DIR/calibration.json (what ran and what was skipped, with residuals) and DIR/preview/*.png, one
// thumbnail per (view, light) of the rectified stack. Nothing is written when the capture is
// refused; files appear only once complete (written beside, then renamed).
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "cli/command.h"
#include "core/error.h"
#include "core/logging.h"
#include "u3m/image_io.h"

namespace u3mscan::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kThumbnailMaxSide = 256;

// One thumbnail: linear RGB scaled by `white`, flagged pixels shown black, at most 256 px a side.
Image Thumbnail(const Observation& observation, double white) {
  const Image& rgb = observation.rgb;
  const double shrink = std::min(1.0, static_cast<double>(kThumbnailMaxSide) / std::max(rgb.width(), rgb.height()));
  const int width = std::max(1, static_cast<int>(rgb.width() * shrink));
  const int height = std::max(1, static_cast<int>(rgb.height() * shrink));
  Image out(width, height, 3);
  for (int c = 0; c < 3; ++c) {
    cv::Mat plane(rgb.height(), rgb.width(), CV_32F, const_cast<float*>(rgb.plane(c).data()));
    cv::Mat masked = plane.clone();
    for (std::size_t i = 0; i < observation.flags.size(); ++i) {
      if (observation.flags[i]) masked.ptr<float>()[i] = 0.0f;
    }
    cv::Mat small(height, width, CV_32F, out.plane(c).data());
    cv::resize(masked / white, small, small.size(), 0, 0, cv::INTER_AREA);
  }
  return out;
}

double StackWhite(const Stack& stack) {
  std::vector<float> values;
  for (const auto& o : stack.observations) {
    for (std::size_t i = 0; i < o.rgb.data().size(); i += 7) values.push_back(o.rgb.data()[i]);
  }
  if (values.empty()) return 1.0;
  const std::size_t k = values.size() * 99 / 100;
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return std::max(1e-9f, values[k]);
}

std::string SafeName(std::string name) {
  for (char& ch : name) {
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '-' && ch != '_') ch = '_';
  }
  return name;
}

struct CalibrateArgs {
  std::string capture;
  std::string output;
  CalibrationOptions options;
  double dpi = 0.0;
  std::vector<double> region_mm;
  std::vector<double> chart_centre_mm;
  bool no_mcc = false;
  bool no_intrinsics = false;
};

int Run(CalibrateArgs& args) {
  if (args.dpi > 0.0) args.options.dpi = args.dpi;
  if (args.region_mm.size() == 4) {
    args.options.region_mm = std::array<double, 4>{args.region_mm[0], args.region_mm[1], args.region_mm[2], args.region_mm[3]};
  }
  if (args.chart_centre_mm.size() == 2) args.options.chart_layout.centre_mm = {args.chart_centre_mm[0], args.chart_centre_mm[1]};
  args.options.use_mcc = !args.no_mcc;
  args.options.calibrate_intrinsics = !args.no_intrinsics;
  if (!args.options.Check()) {
    std::cerr << "u3mscan calibrate: invalid options (side front|back, positive dpi and chart pitch)\n";
    return kExitUsage;
  }
  const Capture capture = Capture::Open(args.capture);
  const ProgressCallback progress = [](std::string_view stage, double fraction) {
    LogDebug() << stage << " " << static_cast<int>(100 * fraction) << " %";
  };
  const CalibrationResult calibration = Calibrate(capture, args.options, progress);
  const Stack stack = BuildStack(capture, calibration, args.options, progress);

  // Everything goes to a staging folder beside the output first; a failure leaves no partial output.
  const fs::path out_dir(args.output);
  fs::create_directories(out_dir);
  const fs::path staging = out_dir / (".calibrate-" + std::to_string(::getpid()));
  fs::create_directories(staging / "preview");
  nlohmann::json json = calibration.ToJson();
  json["preview"] = nlohmann::json::array();
  try {
    const double white = StackWhite(stack);
    ImageWriteOptions png;
    png.format = SampleFormat::kUInt8;
    png.encoding = PixelEncoding::kSrgb;
    for (const auto& observation : stack.observations) {
      const std::string name = SafeName(stack.views[observation.view].camera_id) + "_" +
                               SafeName(stack.lights[observation.light].id) + ".png";
      WriteImageFile(Thumbnail(observation, white), staging / "preview" / name, png);
      json["preview"].push_back({{"file", "preview/" + name},
                                 {"camera", stack.views[observation.view].camera_id},
                                 {"light", stack.lights[observation.light].id},
                                 {"scale", 1.0 / white}});
    }
    {
      std::ofstream file(staging / "calibration.json");
      file << json.dump(2) << "\n";
      if (!file) throw InputError((out_dir / "calibration.json").string(), "", "a writable output folder");
    }
    fs::create_directories(out_dir / "preview");
    for (const auto& entry : fs::directory_iterator(staging / "preview")) {
      fs::rename(entry.path(), out_dir / "preview" / entry.path().filename());
    }
    fs::rename(staging / "calibration.json", out_dir / "calibration.json");
    fs::remove_all(staging);
  } catch (...) {
    std::error_code ignored;
    fs::remove_all(staging, ignored);
    throw;
  }
  std::cout << "calibration: " << (out_dir / "calibration.json").string() << " (" << calibration.steps.size()
            << " steps, " << calibration.warnings.size() << " warnings); preview: " << stack.observations.size()
            << " thumbnails in " << (out_dir / "preview").string() << "\n";
  return kExitOk;
}

U3MSCAN_REGISTER_COMMAND(kCalibrateCommand, "calibrate",
                         "Calibrate a capture folder: calibration.json and a preview of the rectified stack", 20,
                         [](CLI::App& sub) {
                           auto args = std::make_shared<CalibrateArgs>();
                           sub.add_option("CAPTURE", args->capture, "Capture folder (or its capture.json)")->required();
                           sub.add_option("-o,--output", args->output, "Output folder")->required();
                           sub.add_option("--side", args->options.side, "Side to preview: front or back")
                               ->capture_default_str();
                           sub.add_option("--dpi", args->dpi, "Resolution of the grid (default: manifest, else native)");
                           sub.add_option("--region-mm", args->region_mm, "Grid region x0 y0 x1 y1 (mm)")->expected(4);
                           sub.add_option("--chart-centre-mm", args->chart_centre_mm,
                                          "Chart centre x y (mm) when mcc finds no chart")
                               ->expected(2);
                           sub.add_option("--chart-pitch-mm", args->options.chart_layout.patch_pitch_mm,
                                          "Chart patch pitch (mm) when mcc finds no chart (0: searched)")
                               ->capture_default_str();
                           sub.add_flag("--no-mcc", args->no_mcc, "Do not try the mcc chart detector");
                           sub.add_flag("--no-intrinsics", args->no_intrinsics,
                                        "Keep the manifest's intrinsics even with several board frames");
                           return std::function<int()>([args] { return Run(*args); });
                         });

}  // namespace
}  // namespace u3mscan::cli
