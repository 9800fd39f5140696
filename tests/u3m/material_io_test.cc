// Saving and loading materials with their files: .u3m + textures and .u3ma, atomicity, refusals.
#include <gtest/gtest.h>

#include <algorithm>

#include "core/error.h"
#include "u3m/example_material.h"
#include "u3m/material_io.h"
#include "u3m/texture_map.h"
#include "u3m/u3ma_archive.h"
#include "u3m/validate.h"
#include "u3m_test_util.h"

namespace u3mscan {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

constexpr int kSize = 64;
constexpr double kPitchMm = 0.25;  // 64 px = 16 mm at 101.6 dpi
constexpr double kQuantisation8 = 1.0 / 255.0;

// A material with a roughness ramp, a uniform colour and a flat normal map, files in `dir`.
Material MakeMaterial(const fs::path& dir, double roughness_constant = 0.5) {
  Image rough(kSize, kSize, 1, 0.0f, kPitchMm);
  for (int r = 0; r < kSize; ++r)
    for (int c = 0; c < kSize; ++c) rough.at(0, r, c) = static_cast<float>(c) / (kSize - 1);  // mean 0.5
  Image colour(kSize, kSize, 3, 0.2f, kPitchMm);
  Image normal(kSize, kSize, 3, 0.0f, kPitchMm);
  for (int r = 0; r < kSize; ++r)
    for (int c = 0; c < kSize; ++c) normal.at(2, r, c) = 1.0f;
  fs::create_directories(dir / "textures");
  const MapGeometry g = WriteTextureMap(rough, MapKind::kData, dir / "textures/rough.png", SampleFormat::kUInt8);
  WriteTextureMap(colour, MapKind::kColour, dir / "textures/colour.png", SampleFormat::kUInt8);
  WriteTextureMap(normal, MapKind::kNormal, dir / "textures/normal.png", SampleFormat::kUInt16);
  const auto image = [&](const std::string& path) { return TextureImageOf(path, g); };
  Material m;
  m.id = NewUuid4();
  m.name = "io test";
  m.created_ms = m.modified_ms = 1'600'000'000'000;
  Visualization front;
  front.roughness.constant = roughness_constant;
  front.roughness.texture = ScalarTexture{1.0, 0.0, image("textures/rough.png")};
  front.basecolor.constant = Rgb3{0.2, 0.2, 0.2};
  front.basecolor.texture = ColorTexture{BlendMode::kMultiply, Rgb3{}, image("textures/colour.png")};
  front.normal.texture = NormalTexture{1.0, image("textures/normal.png")};
  m.front = front;
  m.custom = ParseJson(test::kForeignCustom, "custom");
  return m;
}

std::vector<std::string> ListTree(const fs::path& dir) {
  std::vector<std::string> names;
  if (!fs::exists(dir)) return names;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) names.push_back(fs::relative(entry.path(), dir).string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(MaterialIo, SavesAndLoadsU3mWithTextures) {
  TempDir src, out;
  const Material m = MakeMaterial(src.path());
  SaveOptions options;
  options.update_modified = false;
  const SaveResult saved = SaveMaterial(m, src.path(), out / "mat.u3m", options);
  EXPECT_EQ(saved.version, SchemaVersion::k1_0);  // nothing needs 1.1
  EXPECT_EQ(ListTree(out.path()), (std::vector<std::string>{"mat.u3m", "textures", "textures/colour.png",
                                                             "textures/normal.png", "textures/rough.png"}));
  const LoadedMaterial loaded = LoadMaterial(out / "mat.u3m");
  EXPECT_TRUE(loaded.material.custom == m.custom);
  EXPECT_EQ(loaded.material.modified_ms, m.modified_ms);
  ASSERT_TRUE(loaded.material.front && loaded.material.front->roughness.texture);
  EXPECT_NEAR(loaded.material.front->roughness.constant, 0.5, kQuantisation8);
  const ValidationReport report = ValidateLoadedMaterial(loaded);
  EXPECT_TRUE(report.valid()) << report.issues.front().pointer << ": " << report.issues.front().message;
}

TEST(MaterialIo, SavesAndLoadsU3maPackage) {
  TempDir src, out;
  const Material m = MakeMaterial(src.path());
  SaveOptions options;
  options.version = SchemaVersion::k1_1;
  const SaveResult saved = SaveMaterial(m, src.path(), out / "mat.u3ma", options);
  EXPECT_EQ(saved.version, SchemaVersion::k1_1);
  EXPECT_EQ(ListTree(out.path()), std::vector<std::string>{"mat.u3ma"});
  const std::vector<ArchiveEntry> entries = ReadArchive(out / "mat.u3ma");
  ASSERT_EQ(entries.size(), 4u);
  EXPECT_EQ(entries.front().name, "mat.u3m");
  fs::path unpacked;
  {
    const LoadedMaterial loaded = LoadMaterial(out / "mat.u3ma");
    unpacked = loaded.base_dir;
    EXPECT_TRUE(fs::exists(unpacked / "textures/rough.png"));
    EXPECT_TRUE(loaded.material.custom == m.custom);
    EXPECT_TRUE(ValidateLoadedMaterial(loaded).valid());
  }
  EXPECT_FALSE(fs::exists(unpacked)) << "the unpacked folder goes with the LoadedMaterial";
  EXPECT_EQ(ListTree(out.path()), std::vector<std::string>{"mat.u3ma"});
}

TEST(MaterialIo, ConstantsBecomeTextureMeansAndGeometryIsFixed) {
  TempDir src, out;
  Material m = MakeMaterial(src.path(), /*roughness_constant=*/0.9);
  m.front->basecolor.constant = Rgb3{0.8, 0.8, 0.8};
  m.front->roughness.texture->image.width_mm = 10.0;  // 64 px cannot be 10 mm at 101.6 dpi
  const SaveResult saved = SaveMaterial(m, src.path(), out / "mat.u3m");
  const Visualization& f = *saved.written.front;
  EXPECT_NEAR(f.roughness.constant, 0.5, kQuantisation8);
  EXPECT_NEAR(f.basecolor.constant.g, 0.2, kQuantisation8);  // linear, not the sRGB code
  EXPECT_NEAR(f.roughness.texture->image.dpi_x, kSize * 25.4 / 10.0, 1e-9);  // size kept, dpi follows
  EXPECT_NEAR(f.roughness.texture->image.height_mm, 10.0, 1e-9);             // square pixels
  EXPECT_FALSE(saved.notes.empty());
  EXPECT_TRUE(ValidateMaterialFile(out / "mat.u3m").valid());
}

TEST(MaterialIo, MissingTextureIsRefusedAndNothingIsWritten) {
  TempDir src, out;
  Material m = MakeMaterial(src.path());
  fs::remove(src / "textures/normal.png");
  try {
    SaveMaterial(m, src.path(), out / "sub/mat.u3m");
    FAIL() << "a missing texture must be refused";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "/material/front/normal/texture/image/path");
  }
  EXPECT_TRUE(ListTree(out.path()).empty());
  // With kDrop the reference goes, with a note.
  SaveOptions drop;
  drop.missing_files = MissingFiles::kDrop;
  const SaveResult saved = SaveMaterial(m, src.path(), out / "mat.u3m", drop);
  EXPECT_FALSE(saved.written.front->normal.texture);
  EXPECT_TRUE(ValidateMaterialFile(out / "mat.u3m").valid());
}

TEST(MaterialIo, ForcedVersionThatCannotHoldIsRefusedAndNothingIsWritten) {
  TempDir src, out;
  Material m = MakeMaterial(src.path());
  m.physics = Physics{};
  SaveOptions options;
  options.version = SchemaVersion::k1_0;
  for (const char* name : {"mat.u3m", "mat.u3ma"}) {
    EXPECT_THROW(SaveMaterial(m, src.path(), out / name, options), InputError) << name;
    EXPECT_TRUE(ListTree(out.path()).empty()) << name;
  }
}

TEST(MaterialIo, ExistingOutputNeedsOverwrite) {
  TempDir src, out;
  const Material m = MakeMaterial(src.path());
  SaveMaterial(m, src.path(), out / "mat.u3m");
  const std::string before = test::ReadFile(out / "mat.u3m");
  EXPECT_THROW(SaveMaterial(m, src.path(), out / "mat.u3m"), InputError);
  EXPECT_EQ(test::ReadFile(out / "mat.u3m"), before);
  SaveOptions overwrite;
  overwrite.overwrite = true;
  EXPECT_NO_THROW(SaveMaterial(m, src.path(), out / "mat.u3m", overwrite));
  // Converting in place (same folder, same textures) works: the files are already there.
  const LoadedMaterial loaded = LoadMaterial(out / "mat.u3m");
  EXPECT_NO_THROW(SaveMaterial(loaded.material, loaded.base_dir, out / "copy.u3m"));
  for (const std::string& name : ListTree(out.path())) EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
}

TEST(MaterialIo, UnwritableNamesAreRenamedToAllowedOnes) {
  TempDir src, out;
  Material m = MakeMaterial(src.path());
  fs::copy_file(src / "textures/rough.png", src / "textures/CON.png");
  fs::copy_file(src / "textures/rough.png", src / "textures/trail.png.");
  m.front->roughness.texture->image.path = "textures/CON.png";
  m.front->displacement.texture = ScalarTexture{1.0, 0.0, m.front->roughness.texture->image};
  m.front->displacement.texture->image.path = "textures/trail.png.";
  const SaveResult saved = SaveMaterial(m, src.path(), out / "mat.u3m");
  EXPECT_EQ(saved.written.front->roughness.texture->image.path, "textures/_CON.png");
  EXPECT_EQ(saved.written.front->displacement.texture->image.path, "textures/trail.png");
  EXPECT_TRUE(fs::exists(out / "textures/_CON.png"));
  EXPECT_TRUE(ValidateMaterialFile(out / "mat.u3m").valid());
}

TEST(MaterialIo, PackageWithTraversalOrTwoMaterialsIsRefusedWithoutLeftovers) {
  TempDir dir;
  const std::string bad = test::Inline11();
  const std::string traversal = [&] {
    std::string t = bad;
    return t.replace(t.find("textures/disp.png"), 17, "../../../tmp/evil");
  }();
  const auto leftovers = [] {
    int n = 0;
    for (const auto& e : fs::directory_iterator(fs::temp_directory_path()))
      n += e.path().filename().string().rfind("u3mscan-u3ma-", 0) == 0;
    return n;
  };
  const int before = leftovers();
  WriteArchive(dir / "traversal.u3ma", {{"a.u3m", std::vector<std::uint8_t>(traversal.begin(), traversal.end())}});
  EXPECT_THROW(LoadMaterial(dir / "traversal.u3ma"), InputError);
  WriteArchive(dir / "two.u3ma", {{"a.u3m", std::vector<std::uint8_t>(bad.begin(), bad.end())},
                                  {"b.u3m", std::vector<std::uint8_t>(bad.begin(), bad.end())}});
  EXPECT_THROW(LoadMaterial(dir / "two.u3ma"), InputError);
  const std::string garbage = "PK not really a zip";
  test::WriteFile(dir / "garbage.u3ma", garbage);
  EXPECT_THROW(LoadMaterial(dir / "garbage.u3ma"), InputError);
  EXPECT_EQ(leftovers(), before);
  EXPECT_FALSE(fs::exists("/tmp/evil"));
}

TEST(MaterialIo, ExampleMaterialIsCompleteAndValidInEveryForm) {
  TempDir out;
  for (const auto& [name, version] : std::vector<std::pair<std::string, std::optional<SchemaVersion>>>{
           {"auto/ex.u3m", std::nullopt}, {"v10/ex.u3m", SchemaVersion::k1_0}, {"v11/ex.u3ma", SchemaVersion::k1_1}}) {
    ExampleOptions options;
    options.size_px = kSize;
    options.version = version;
    const SaveResult saved = WriteExampleMaterial(out / name, options);
    EXPECT_EQ(saved.version, version.value_or(SchemaVersion::k1_1)) << name;
    const ValidationReport report = ValidateMaterialFile(out / name);
    EXPECT_EQ(report.errors(), 0) << name << ": " << report.issues.front().pointer << " " << report.issues.front().message;
    EXPECT_EQ(report.warnings(), 0) << name;
    const LoadedMaterial loaded = LoadMaterial(out / name);
    ASSERT_TRUE(loaded.material.front);
    for (const char* key : {"basecolor", "normal", "roughness", "displacement"}) {
      Visualization copy = *loaded.material.front;
      const auto refs = TextureImages(copy);
      EXPECT_TRUE(std::any_of(refs.begin(), refs.end(), [&](const TextureRef& r) { return r.key == key; })) << key;
    }
    ASSERT_NE(loaded.material.custom.Find("u3mscan"), nullptr);
    EXPECT_NE(loaded.material.custom.Find("u3mscan")->Find("displacement"), nullptr);
  }
}

}  // namespace
}  // namespace u3mscan
