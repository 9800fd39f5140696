// Truth files: every map and the JSON written, read back identical, written atomically.

#include "datasets_synthetic/truth_writer.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "core/error.h"

namespace u3mscan::synthetic {
namespace {

namespace fs = std::filesystem;

fs::path FreshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("u3mscan_truth_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  return dir;
}

SceneTruth Lace() {
  SceneOptions o;
  o.width = 48;
  o.height = 40;
  o.seed = 3;
  return MakeScene("lace", o);
}

TEST(TruthWriterTest, WritesMapsAndJsonThatReadBackIdentical) {
  const fs::path root = FreshDir("roundtrip");
  const fs::path dir = root / "truth";
  const SceneTruth truth = Lace();
  const nlohmann::json rig = {{"lights", {{{"id", "L0"}, {"direction", {0.0, 0.5, 0.866}}}}},
                              {"cameras", nlohmann::json::array()}};
  WriteTruth(truth, rig, dir);
  for (const char* map : {"height_mm", "normal", "base_color", "roughness", "specular", "specular_tint", "sheen",
                          "sheen_tint", "metallic", "anisotropic", "alpha", "tangent"}) {
    EXPECT_TRUE(fs::exists(dir / (std::string(map) + ".exr"))) << map;
  }
  nlohmann::json doc;
  const SceneTruth back = ReadTruth(dir, &doc);
  EXPECT_EQ(doc["lights"], rig["lights"]);
  EXPECT_EQ(doc["scene"], "lace");
  EXPECT_EQ(doc["seed"], 3);
  EXPECT_EQ(doc["grid"]["width"], 48);
  EXPECT_EQ(doc["grid"]["height"], 40);
  EXPECT_EQ(doc["reflectance_model"], "principled");
  EXPECT_LT(doc["means"]["alpha"].get<double>(), 1.0);
  EXPECT_EQ(doc["yarns"].size(), truth.yarns.size());
  EXPECT_EQ(back.name, truth.name);
  EXPECT_EQ(back.seed, truth.seed);
  EXPECT_DOUBLE_EQ(back.pitch_mm, truth.pitch_mm);
  EXPECT_DOUBLE_EQ(back.height_max_mm, truth.height_max_mm);
  EXPECT_DOUBLE_EQ(back.repeat_x_mm, truth.repeat_x_mm);
  ASSERT_EQ(back.yarns.size(), truth.yarns.size());
  EXPECT_EQ(back.yarns[0].name, truth.yarns[0].name);
  EXPECT_FLOAT_EQ(back.yarns[0].roughness, truth.yarns[0].roughness);
  // Float EXR: bit-exact.
  EXPECT_EQ(back.height_mm.data(), truth.height_mm.data());
  EXPECT_EQ(back.normal.data(), truth.normal.data());
  EXPECT_EQ(back.base_color.data(), truth.base_color.data());
  EXPECT_EQ(back.alpha.data(), truth.alpha.data());
  EXPECT_EQ(back.tangent.data(), truth.tangent.data());
  EXPECT_EQ(back.sheen.data(), truth.sheen.data());
  fs::remove_all(root);
}

TEST(TruthWriterTest, ReplacesAnOlderTruthAndLeavesNoTemporaries) {
  const fs::path root = FreshDir("replace");
  const fs::path dir = root / "truth";
  WriteTruth(Lace(), nullptr, dir);
  SceneOptions o;
  o.width = 16;
  o.height = 16;
  const SceneTruth second = MakeScene("mirror", o);
  WriteTruth(second, nullptr, dir);
  EXPECT_EQ(ReadTruth(dir).name, "mirror");
  int entries = 0;
  for (const auto& entry : fs::directory_iterator(root)) {
    (void)entry;
    ++entries;
  }
  EXPECT_EQ(entries, 1);  // only truth/
  fs::remove_all(root);
}

TEST(TruthWriterTest, ReservedExtraMembersAreRefusedBeforeWriting) {
  const fs::path root = FreshDir("reserved");
  EXPECT_THROW(WriteTruth(Lace(), {{"scene", "other"}}, root / "truth"), std::invalid_argument);
  EXPECT_THROW(WriteTruth(Lace(), nlohmann::json::array(), root / "truth"), std::invalid_argument);
  EXPECT_FALSE(fs::exists(root / "truth"));
  fs::remove_all(root);
}

TEST(TruthWriterTest, BadTruthJsonNamesFileAndField) {
  const fs::path root = FreshDir("bad");
  const fs::path dir = root / "truth";
  WriteTruth(Lace(), nullptr, dir);
  {
    std::ifstream in(dir / "truth.json");
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["grid"]["pitch_mm"] = "wide";
    std::ofstream out(dir / "truth.json");
    out << doc.dump();
  }
  try {
    ReadTruth(dir);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "/grid/pitch_mm");
    EXPECT_NE(e.file().find("truth.json"), std::string::npos);
  }
  EXPECT_THROW(ReadTruth(root / "missing"), InputError);
  fs::remove_all(root);
}

}  // namespace
}  // namespace u3mscan::synthetic
