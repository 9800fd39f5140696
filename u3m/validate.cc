#include "u3m/validate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <system_error>

#include "core/error.h"
#include "core/units.h"
#include "u3m/image_io.h"
#include "u3m/texture_stats.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

std::string Fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.4g", v);
  return buffer;
}

class FileChecker {
 public:
  FileChecker(const LoadedMaterial& loaded, const ValidationOptions& options, std::vector<Issue>& issues)
      : loaded_(loaded), options_(options), issues_(issues) {}

  void Error(const std::string& pointer, std::string message) {
    issues_.push_back({IssueSeverity::kError, pointer, std::move(message)});
  }

  // Existence and readability; returns false when the file cannot be used further.
  bool Exists(const std::string& path, const std::string& pointer) {
    std::error_code ec;
    if (!fs::is_regular_file(loaded_.Resolve(path), ec)) {
      Error(pointer, "file \"" + path + "\" not found");
      return false;
    }
    return true;
  }

  bool Info(const std::string& path, const std::string& pointer, ImageReadInfo& info) {
    if (!Exists(path, pointer)) return false;
    try {
      info = ReadImageInfo(loaded_.Resolve(path));
      return true;
    } catch (const InputError& e) {
      Error(pointer, "\"" + path + "\" is not a readable image: " + e.expected());
      return false;
    }
  }

  void Geometry(const ImageReadInfo& info, double width_mm, double height_mm, double dpi_x, double dpi_y,
                const std::string& pointer) {
    const auto check = [&](int px, double mm, double dpi, const char* axis) {
      if (PixelSizeAgrees(px, mm, dpi)) return;
      Error(pointer + "/" + axis, std::to_string(px) + " px do not agree with " + Fmt(mm) + " mm at " + Fmt(dpi) +
                                      " dpi (expected " + Fmt(mm * dpi / kMmPerInch) + " px within 2 % or 1 px)");
    };
    check(info.width, width_mm, dpi_x, "width");
    check(info.height, height_mm, dpi_y, "height");
  }

  std::optional<Image> Load(const std::string& path, PixelEncoding encoding, const std::string& pointer) {
    try {
      return ReadImageFile(loaded_.Resolve(path), encoding);
    } catch (const InputError& e) {
      Error(pointer, "\"" + path + "\" cannot be read: " + e.expected());
      return std::nullopt;
    }
  }

  // Colour maps are sRGB-encoded; data maps (scalars, normals) are linear (docs/u3m-conventions.md).
  static PixelEncoding EncodingOf(const ScalarParam&) { return PixelEncoding::kLinear; }
  static PixelEncoding EncodingOf(const ColorParam&) { return PixelEncoding::kSrgb; }
  static PixelEncoding EncodingOf(const NormalParam&) { return PixelEncoding::kLinear; }

  // Whether the constant can be compared with this texture; errors for what the image lacks.
  bool Comparable(const ScalarParam&, const ImageReadInfo&, const std::string&) { return true; }
  bool Comparable(const ColorParam&, const ImageReadInfo&, const std::string&) { return true; }
  bool Comparable(const NormalParam& p, const ImageReadInfo& info, const std::string& path_pointer) {
    if (info.channels < 3)
      Error(path_pointer, "a normal map needs 3 channels, \"" + p.texture->image.path + "\" has " +
                              std::to_string(info.channels));
    // 1.0 has no constant normal vector: nothing to compare.
    return loaded_.version != SchemaVersion::k1_0 && info.channels >= 3;
  }

  // The constant against the texture's mean final value (offset + average(channels) * factor, the
  // colour after its blend mode, the normal after its scale).
  void Constant(const ScalarParam& p, const Image& image, const std::string& pointer) {
    const double mean = ScalarTextureMean(image, p.texture->factor, p.texture->offset);
    if (!ConstantAgrees(p.constant, mean))
      Error(pointer, "constant " + Fmt(p.constant) + " is not the texture's mean value " + Fmt(mean) +
                         " (offset + average(channels) * factor); a reader without the texture gets it wrong");
  }
  void Constant(const ColorParam& p, const Image& image, const std::string& pointer) {
    const Rgb3 mean = ColorTextureMean(image, p.texture->mode, p.texture->factor);
    if (!ConstantAgrees(p.constant.r, mean.r) || !ConstantAgrees(p.constant.g, mean.g) ||
        !ConstantAgrees(p.constant.b, mean.b))
      Error(pointer, "constant (" + Fmt(p.constant.r) + ", " + Fmt(p.constant.g) + ", " + Fmt(p.constant.b) +
                         ") is not the texture's mean linear colour (" + Fmt(mean.r) + ", " + Fmt(mean.g) + ", " +
                         Fmt(mean.b) + ") after mode " + std::string(BlendModeName(p.texture->mode)));
  }
  void Constant(const NormalParam& p, const Image& image, const std::string& pointer) {
    const Vec3 mean = NormalTextureMean(image, p.texture->scale);
    const Vec3& c = p.constant;
    if (std::abs(c.x - mean.x) > kNormalConstantTolerance || std::abs(c.y - mean.y) > kNormalConstantTolerance ||
        std::abs(c.z - mean.z) > kNormalConstantTolerance)
      Error(pointer, "constant (" + Fmt(c.x) + ", " + Fmt(c.y) + ", " + Fmt(c.z) + ") is not the texture's mean normal (" +
                         Fmt(mean.x) + ", " + Fmt(mean.y) + ", " + Fmt(mean.z) + ")");
  }

  // Every textured parameter of one key table (ScalarKeys, ColorKeys or NormalKeys) on a side: the
  // file exists and is an image, its pixel size agrees with its size and dpi, and (check_constants)
  // the constant agrees with the texture's mean. The overloads above hold what differs by type.
  template <class Key>
  void Textures(const Visualization& side, const std::string& sp, const std::vector<Key>& keys) {
    for (const Key& key : keys) {
      const auto& p = side.*key.member;
      if (!p.texture) continue;
      const std::string kp = sp + "/" + std::string(key.name);
      const std::string ip = kp + "/texture/image";
      const TextureImage& i = p.texture->image;
      ImageReadInfo info;
      if (!Info(i.path, ip + "/path", info)) continue;
      Geometry(info, i.width_mm, i.height_mm, i.dpi_x, i.dpi_y, ip);
      const bool comparable = Comparable(p, info, ip + "/path");
      if (!options_.check_constants || !comparable) continue;
      if (auto image = Load(i.path, EncodingOf(p), ip + "/path")) Constant(p, *image, kp + "/constant");
    }
  }

  void Side(const Visualization& side, const std::string& sp) {
    Textures(side, sp, ScalarKeys());
    Textures(side, sp, ColorKeys());
    Textures(side, sp, NormalKeys());
    if (side.preview) {
      const PreviewImage& pv = *side.preview;
      ImageReadInfo info;
      if (Info(pv.path, sp + "/preview/path", info))
        Geometry(info, pv.width_mm, pv.height_mm, pv.dpi_x, pv.dpi_y, sp + "/preview");
    }
  }

  void Run() {
    const Material& m = loaded_.material;
    for (const auto& [name, side] : Sides(m)) Side(*side, "/material/" + std::string(name));
    if (m.physics && !m.physics->fab_path.empty()) Exists(m.physics->fab_path, "/material/physics/devices/fab");
  }

 private:
  const LoadedMaterial& loaded_;
  const ValidationOptions& options_;
  std::vector<Issue>& issues_;
};

}  // namespace

int ValidationReport::errors() const {
  return static_cast<int>(std::count_if(issues.begin(), issues.end(), [](const Issue& i) { return i.severity == IssueSeverity::kError; }));
}

int ValidationReport::warnings() const { return static_cast<int>(issues.size()) - errors(); }

ValidationReport ValidateLoadedMaterial(const LoadedMaterial& loaded, const ValidationOptions& options) {
  ValidationReport report;
  report.file = loaded.source.string();
  report.version = loaded.version;
  report.issues = loaded.issues;
  if (options.check_files) FileChecker(loaded, options, report.issues).Run();
  return report;
}

ValidationReport ValidateMaterialFile(const fs::path& path, const ValidationOptions& options) {
  return ValidateLoadedMaterial(LoadMaterial(path), options);
}

}  // namespace u3mscan
