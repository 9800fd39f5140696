// `u3mscan integrate NORMALS --pitch-mm P -o HEIGHT.exr [--mask M] [--integrator dct|robust]`:
// normal integration alone on any normal map (docs/reconstruction.md).
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include "cli/command.h"
#include "core/error.h"
#include "core/logging.h"
#include "reconstruction/normal_integration.h"
#include "u3m/image_io.h"

namespace u3mscan::cli {
namespace {

namespace fs = std::filesystem;
using reconstruction::IntegrationOptions;

struct IntegrateArgs {
  std::string normals_path;
  std::string output_path;
  std::string mask_path;
  std::string integrator = "dct";
  IntegrationOptions options;
};

// Normals in world/tangent frame (x right, y up, z out). Float files hold the vector itself;
// integer files (PNG/TIFF, as in a U3M normal texture) hold (n + 1) / 2 and are decoded.
Image ReadNormals(const std::string& path) {
  ImageReadInfo info;
  Image file = ReadImageFile(path, PixelEncoding::kLinear, &info);
  if (file.channels() < 3)
    throw InputError(path, "channels", "a normal map with 3 channels (x, y, z), got " + std::to_string(file.channels()));
  Image normal(file.width(), file.height(), 3);
  const std::size_t n = file.pixel_count();
  const bool encoded = info.format != SampleFormat::kFloat32;
  for (int c = 0; c < 3; ++c)
    for (std::size_t i = 0; i < n; ++i) {
      const float v = file.data()[c * n + i];
      normal.data()[c * n + i] = encoded ? 2.0f * v - 1.0f : v;
    }
  return normal;
}

int Run(IntegrateArgs& args) {
  const auto start = std::chrono::steady_clock::now();
  args.options.method = reconstruction::ParseIntegrator(args.integrator);
  const fs::path out(args.output_path);
  const std::string ext = out.extension().string();
  if (ext != ".exr" && ext != ".tif" && ext != ".tiff")
    throw InputError(args.output_path, "extension", "a float image file (.exr, .tif or .tiff) for heights in mm");

  Image normal = ReadNormals(args.normals_path);
  normal.set_pitch_mm(args.options.pitch_mm);
  Image mask;
  if (!args.mask_path.empty()) {
    Image file = ReadImageFile(args.mask_path, PixelEncoding::kLinear);
    if (file.width() != normal.width() || file.height() != normal.height())
      throw InputError(args.mask_path, "size",
                       std::to_string(normal.width()) + "x" + std::to_string(normal.height()) +
                           " pixels like the normal map, got " + std::to_string(file.width()) + "x" +
                           std::to_string(file.height()));
    // First channel, 0 = outside, 1 = inside (fractions weight the pixel).
    mask = Image(file.width(), file.height(), 1);
    std::copy(file.plane(0).begin(), file.plane(0).end(), mask.data().begin());
  }
  const auto read_done = std::chrono::steady_clock::now();

  const reconstruction::IntegrationResult result = reconstruction::IntegrateNormals(normal, mask, args.options);
  const auto solve_done = std::chrono::steady_clock::now();

  ImageWriteOptions write;
  write.format = SampleFormat::kFloat32;
  write.encoding = PixelEncoding::kLinear;
  write.dpi = 25.4 / args.options.pitch_mm;
  WriteImageFile(result.height_mm, out, write);  // atomic: temp file + rename
  const auto write_done = std::chrono::steady_clock::now();

  auto seconds = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  float lo = 0.0f, hi = 0.0f;
  if (!result.height_mm.empty()) {
    const auto [mn, mx] = std::minmax_element(result.height_mm.data().begin(), result.height_mm.data().end());
    lo = *mn, hi = *mx;
  }
  LogInfo() << "integrate: " << normal.width() << "x" << normal.height() << " px at " << args.options.pitch_mm
            << " mm, " << args.integrator << " integrator: heights " << lo << " .. " << hi << " mm ("
            << result.robust_iterations << " robust rounds, " << result.cg_iterations << " CG iterations)";
  LogInfo() << "integrate: read " << seconds(start, read_done) << " s, integrate " << seconds(read_done, solve_done)
            << " s, write " << seconds(solve_done, write_done) << " s -> " << out.string();
  return kExitOk;
}

U3MSCAN_REGISTER_COMMAND(kIntegrateCommand, "integrate", "Integrate a normal map into a height map (mm)", 40,
                         [](CLI::App& sub) {
                           auto args = std::make_shared<IntegrateArgs>();
                           sub.add_option("normals", args->normals_path,
                                          "Normal map (float EXR/TIFF as is; 8/16-bit PNG/TIFF decoded from (n+1)/2)")
                               ->required()
                               ->check(CLI::ExistingFile);
                           sub.add_option("--pitch-mm", args->options.pitch_mm, "Pixel pitch on the sample, mm")
                               ->required()
                               ->check(CLI::Range(1e-6, 1e3));
                           sub.add_option("-o,--output", args->output_path, "Height map to write (.exr), mm")->required();
                           sub.add_option("--mask", args->mask_path,
                                          "Valid region: first channel, 0 = outside, 1 = inside")
                               ->check(CLI::ExistingFile);
                           sub.add_option("--integrator", args->integrator,
                                          "dct: fast Poisson (default); robust: keeps discontinuities")
                               ->check(CLI::IsMember({"dct", "robust"}));
                           sub.add_option("--mean-height-mm", args->options.mean_height_mm,
                                          "Mean height of the valid pixels, mm (default 0)");
                           return std::function<int()>([args] { return Run(*args); });
                         });

}  // namespace
}  // namespace u3mscan::cli
