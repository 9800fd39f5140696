// Validation of files: existence, pixel size against size and dpi, constants against texture means.
#include <gtest/gtest.h>

#include <algorithm>

#include "core/error.h"
#include "u3m/material_io.h"
#include "u3m/texture_map.h"
#include "u3m/validate.h"
#include "u3m_test_util.h"

namespace u3mscan {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

constexpr int kSize = 64;
constexpr double kDpi = 254.0;  // 0.1 mm pixels: 64 px = 6.4 mm
constexpr double kWidthMm = kSize * 25.4 / kDpi;

bool HasError(const ValidationReport& report, const std::string& pointer) {
  return std::any_of(report.issues.begin(), report.issues.end(),
                     [&](const Issue& i) { return i.pointer == pointer && i.severity == IssueSeverity::kError; });
}

// Writes a 1.1 material by hand (no writer help) with one uniform grey sRGB basecolor map (code
// 128 -> linear 0.2158) and one roughness map of value 0.4, then returns its path.
fs::path WriteCase(const TempDir& dir, double colour_constant, double roughness_constant, double width_mm,
                   bool with_file = true) {
  if (with_file) {
    fs::create_directories(dir / "textures");
    Image colour(kSize, kSize, 3, 0.2158605f);
    WriteTextureMap(colour, MapKind::kColour, dir / "textures/c.png", SampleFormat::kUInt8);
    Image rough(kSize, kSize, 1, 0.4f);
    WriteTextureMap(rough, MapKind::kData, dir / "textures/r.png", SampleFormat::kUInt8);
  }
  Material m;
  m.id = NewUuid4();
  m.name = "validate";
  Visualization f;
  TextureImage image{"textures/c.png", width_mm, kWidthMm, kDpi, kDpi, 0.0, RepeatMode::kNormal};
  f.basecolor.constant = Rgb3{colour_constant, colour_constant, colour_constant};
  f.basecolor.texture = ColorTexture{BlendMode::kMultiply, Rgb3{}, image};
  image.path = "textures/r.png";
  f.roughness.constant = roughness_constant;
  f.roughness.texture = ScalarTexture{1.0, 0.0, image};
  m.front = f;
  MaterialWriteOptions options;
  options.version = SchemaVersion::k1_1;
  test::WriteFile(dir / "m.u3m", WriteMaterialJson(m, options, "m.u3m").text);
  return dir / "m.u3m";
}

TEST(Validate, AConsistentMaterialIsValid) {
  TempDir dir;
  const ValidationReport report = ValidateMaterialFile(WriteCase(dir, 0.2158605, 0.4, kWidthMm));
  EXPECT_TRUE(report.valid()) << report.issues.front().pointer << ": " << report.issues.front().message;
  EXPECT_EQ(report.warnings(), 0);
}

TEST(Validate, ColourConstantIsComparedInLinearRgb) {
  TempDir dir;
  // 0.5 is the sRGB code value of the map, not its linear mean.
  const ValidationReport report = ValidateMaterialFile(WriteCase(dir, 0.5, 0.4, kWidthMm));
  EXPECT_TRUE(HasError(report, "/material/front/basecolor/constant"));
  EXPECT_FALSE(HasError(report, "/material/front/roughness/constant"));
}

TEST(Validate, ScalarConstantFarFromTheMeanIsAnError) {
  TempDir dir;
  const ValidationReport report = ValidateMaterialFile(WriteCase(dir, 0.2158605, 0.7, kWidthMm));
  EXPECT_TRUE(HasError(report, "/material/front/roughness/constant"));
  ValidationOptions no_constants;
  no_constants.check_constants = false;
  EXPECT_TRUE(ValidateMaterialFile(dir / "m.u3m", no_constants).valid());
}

TEST(Validate, PixelSizeMustAgreeWithSizeAndDpi) {
  TempDir dir;
  // 3 % too wide: more than 2 % and more than 1 px (64 px).
  const ValidationReport wide = ValidateMaterialFile(WriteCase(dir, 0.2158605, 0.4, kWidthMm * 1.03));
  EXPECT_TRUE(HasError(wide, "/material/front/basecolor/texture/image/width"));
  EXPECT_FALSE(HasError(wide, "/material/front/basecolor/texture/image/height"));
  // Half a pixel off is within tolerance.
  TempDir dir2;
  EXPECT_TRUE(ValidateMaterialFile(WriteCase(dir2, 0.2158605, 0.4, kWidthMm * (kSize + 0.5) / kSize)).valid());
}

TEST(Validate, MissingFilesAreErrorsWithTheirPointer) {
  TempDir dir;
  const ValidationReport report = ValidateMaterialFile(WriteCase(dir, 0.2, 0.4, kWidthMm, /*with_file=*/false));
  EXPECT_TRUE(HasError(report, "/material/front/basecolor/texture/image/path"));
  EXPECT_TRUE(HasError(report, "/material/front/roughness/texture/image/path"));
  test::WriteFile(dir / "textures/c.png", "not an image");
  EXPECT_TRUE(HasError(ValidateMaterialFile(dir / "m.u3m"), "/material/front/basecolor/texture/image/path"));
}

TEST(Validate, UnreadableFileThrows) {
  TempDir dir;
  test::WriteFile(dir / "x.u3m", "{\"schema\": \"1.1\", ");
  EXPECT_THROW(ValidateMaterialFile(dir / "x.u3m"), InputError);
  EXPECT_THROW(ValidateMaterialFile(dir / "missing.u3m"), InputError);
  EXPECT_THROW(ValidateMaterialFile(dir / "x.txt"), InputError);
}

TEST(ValidateSamples, TheFleecePackageShowsItsKnownProblems) {
  if (!test::SharedReferencePresent()) GTEST_SKIP() << "no " << test::SharedReference() << ": sample tests skipped";
  const ValidationReport report = ValidateMaterialFile(test::SharedReference() / "samples/browzwear-1.1-polartec-fleece.u3ma");
  EXPECT_FALSE(report.valid());
  EXPECT_TRUE(HasError(report, "/material/created"));
  EXPECT_TRUE(HasError(report, "/material/front/preview/width"));          // preview sizes ten times off
  EXPECT_TRUE(HasError(report, "/material/front/metalness/constant"));     // 1 written for 0
  EXPECT_FALSE(HasError(report, "/material/front/roughness/texture/image/width"));  // textures agree
}

}  // namespace
}  // namespace u3mscan
