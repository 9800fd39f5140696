// The material writer's anisotropy rotation: the fit's turn in degrees becomes U3M
// anisotropy_rotation, a constant or a texture of rotation / 180 with factor 180, in degrees in 1.0
// and in turns in 1.1 (u3m/ converts), with the constant equal to the texture's mean.
#include "pipeline/material_writer.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/support/temp_dir.h"
#include "u3m/material_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr int kSize = 16;
constexpr double kPitchMm = 0.1;
constexpr double kRotationFactorDeg = 180.0;
// A 16-bit texture holds rotation / 180 to 1/65535: 0.003 degrees; the mean of the quantised map.
constexpr double kQuantisedDeg = 0.01;

SideMaps FlatSide() {
  SideMaps side;
  side.base_color = Image(kSize, kSize, 3, 0.4f, kPitchMm);
  side.normal = Image(kSize, kSize, 3, 0.0f, kPitchMm);
  for (float& v : side.normal.plane(2)) v = 1.0f;
  side.height_mm = Image(kSize, kSize, 1, 0.0f, kPitchMm);
  return side;
}

// Left half turned by 90 degrees, right half unturned: a texture.
ScalarMapChoice HalfTurnedRotation() {
  ScalarMapChoice choice;
  choice.u3m_key = "anisotropy_rotation";
  choice.source = ParameterSource::kMeasured;
  choice.map = Image(kSize, kSize, 1, 0.0f, kPitchMm);
  for (int row = 0; row < kSize; ++row) {
    for (int col = 0; col < kSize / 2; ++col) choice.map.at(0, row, col) = static_cast<float>(90.0 / kRotationFactorDeg);
  }
  choice.texture_factor = kRotationFactorDeg;
  choice.value = 45.0;
  choice.reason = "one turn per cluster (texture)";
  return choice;
}

nlohmann::json ReadJson(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

// Degrees per unit of the file's anisotropy_rotation: 1 in 1.0, 360 (one turn) in 1.1.
double FileUnitPerDegree(const std::string& schema) { return schema == "1.0" ? 1.0 : 1.0 / 360.0; }

class RotationWriter : public ::testing::TestWithParam<const char*> {
 protected:
  // Writes one flat side with `rotation` into the test's folder in the parameter's schema.
  fs::path WriteWith(const ScalarMapChoice& rotation) {
    ScanMaterialRequest request;
    request.name = "turned";
    request.file_stem = "turned";
    request.schema = GetParam();
    SideMaps side = FlatSide();
    side.scalars.push_back(rotation);
    request.sides.push_back(side);
    return WriteScanMaterial(request, dir_.path(), /*overwrite=*/false).material_path;
  }

 private:
  test::TempDir dir_;
};

TEST_P(RotationWriter, TextureHoldsDegreesOverAHalfTurnAndTheConstantIsItsMean) {
  const fs::path material = WriteWith(HalfTurnedRotation());
  // The model (degrees in both versions).
  const LoadedMaterial loaded = LoadMaterial(material);
  ASSERT_TRUE(loaded.material.front.has_value());
  const ScalarParam& rotation = loaded.material.front->anisotropy_rotation;
  ASSERT_TRUE(rotation.texture.has_value()) << "a half-turned map is a texture";
  EXPECT_NEAR(rotation.texture->factor, kRotationFactorDeg, 1e-9);
  EXPECT_NEAR(rotation.constant, 45.0, kQuantisedDeg) << "the constant is the texture's mean";
  // The file: degrees in 1.0, fractions of a turn in 1.1.
  const nlohmann::json field = ReadJson(material)["material"]["front"]["anisotropy_rotation"];
  const double per_unit = FileUnitPerDegree(GetParam());
  EXPECT_NEAR(field["texture"]["factor"].get<double>(), kRotationFactorDeg * per_unit, 1e-9) << field.dump();
  EXPECT_NEAR(field["constant"].get<double>(), 45.0 * per_unit, kQuantisedDeg * per_unit) << field.dump();
}

TEST_P(RotationWriter, ConstantTurnHasNoTexture) {
  ScalarMapChoice choice;
  choice.u3m_key = "anisotropy_rotation";
  choice.source = ParameterSource::kConstant;
  choice.value = 90.0;
  const fs::path material = WriteWith(choice);
  const LoadedMaterial loaded = LoadMaterial(material);
  ASSERT_TRUE(loaded.material.front.has_value());
  EXPECT_FALSE(loaded.material.front->anisotropy_rotation.texture.has_value());
  EXPECT_NEAR(loaded.material.front->anisotropy_rotation.constant, 90.0, 1e-9);
  const nlohmann::json field = ReadJson(material)["material"]["front"]["anisotropy_rotation"];
  EXPECT_NEAR(field["constant"].get<double>(), 90.0 * FileUnitPerDegree(GetParam()), 1e-9) << field.dump();
}

INSTANTIATE_TEST_SUITE_P(Schemas, RotationWriter, ::testing::Values("1.0", "1.1"),
                         [](const ::testing::TestParamInfo<const char*>& info) {
                           return std::string(info.param) == "1.0" ? std::string("V10") : std::string("V11");
                         });

}  // namespace
}  // namespace u3mscan
