// Every file the writer produces passes the official JSON schema of its version, run by Debian's
// python3-jsonschema with its FormatChecker (plus a strict date-time check, see check_schema.py).
#include <gtest/gtest.h>

#include <cstdlib>

#include "u3m/example_material.h"
#include "u3m/material_io.h"
#include "u3m/material_json.h"
#include "u3m_test_util.h"

namespace u3mscan {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

std::string Quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Runs the checker on `files`; returns its exit code and puts its report in `report`.
int RunSchemaChecker(const std::vector<fs::path>& files, const fs::path& log, std::string& report) {
  std::string command = Quote(U3MSCAN_SYSTEM_PYTHON) + " " + Quote(U3MSCAN_SCHEMA_CHECKER) + " " +
                        Quote(test::SharedReference().string());
  for (const fs::path& file : files) {
    command += ' ';
    command += Quote(file.string());
  }
  command += " > ";  // appended piecewise: GCC 12 warns falsely (-Wrestrict) on "literal" + temporary
  command += Quote(log.string());
  command += " 2>&1";
  const int status = std::system(command.c_str());
  report = test::ReadFile(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class Schema : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!test::SharedReferencePresent())
      GTEST_SKIP() << "official schemas not found under " << test::SharedReference()
                   << ": schema validation with python3-jsonschema SKIPPED";
    if (std::string(U3MSCAN_SYSTEM_PYTHON).empty() || !fs::exists(U3MSCAN_SYSTEM_PYTHON))
      GTEST_SKIP() << "no system python3 (python3-jsonschema): schema validation SKIPPED";
  }
};

TEST_F(Schema, CheckerRejectsTheZoneLessSamplesSoItCanFail) {
  TempDir dir;
  std::string report;
  const fs::path sample = test::SharedReference() / "samples/browzwear-1.1-front-back/Fleece_60_Cotton_40_Poly_304gsm.u3m";
  EXPECT_EQ(RunSchemaChecker({sample}, dir / "log.txt", report), 1) << report;
  EXPECT_NE(report.find("/material/created"), std::string::npos) << report;
}

TEST_F(Schema, EveryWrittenFilePassesTheOfficialSchema) {
  TempDir dir;
  std::vector<fs::path> files;
  const auto write = [&](const Material& m, std::optional<SchemaVersion> version, const std::string& name) {
    MaterialWriteOptions options;
    options.version = version;
    test::WriteFile(dir / name, WriteMaterialJson(m, options, name).text);
    files.push_back(dir / name);
  };
  // Inline documents through every version path, including tolerated deviations and 1.0 nulls.
  const Material m11 = ReadMaterialJson(test::Inline11(), "inline11").material;
  const Material m10 = ReadMaterialJson(test::Inline10(), "inline10").material;
  const Material m10null = ReadMaterialJson(test::Inline10("null"), "inline10null").material;
  write(m11, std::nullopt, "m11_auto.u3m");
  write(m10, std::nullopt, "m10_auto.u3m");
  write(m10, SchemaVersion::k1_1, "m10_to_11.u3m");
  write(m10null, SchemaVersion::k1_0, "m10null.u3m");
  write(m10null, SchemaVersion::k1_1, "m10null_to_11.u3m");
  write(ReadMaterialJson(test::ReadFile(dir / "m10_to_11.u3m"), "x").material, SchemaVersion::k1_0, "m10_11_10.u3m");
  Material everything = m11;
  everything.back = everything.front;
  everything.side = Visualization{};
  everything.physics->fab_path = "physics/fab.json";
  write(everything, std::nullopt, "everything.u3m");
  Material minimal;
  minimal.id = NewUuid4();
  minimal.name = "m";
  write(minimal, SchemaVersion::k1_0, "minimal10.u3m");
  minimal.physics = Physics{};
  write(minimal, std::nullopt, "minimal11.u3m");
  // The samples, rewritten.
  for (const char* sample : {"samples/browzwear-1.1-front-back/Fleece_60_Cotton_40_Poly_304gsm.u3m", "1.0/Example_1.0.u3m"}) {
    const Material m = ReadMaterialJson(test::ReadFile(test::SharedReference() / sample), sample).material;
    write(m, std::nullopt, fs::path(sample).stem().string() + "_rewritten.u3m");
  }
  // The example material in each version, and a converted package.
  for (const auto& [name, version] : std::vector<std::pair<std::string, std::optional<SchemaVersion>>>{
           {"ex10/ex.u3m", SchemaVersion::k1_0}, {"ex11/ex.u3m", std::nullopt}}) {
    ExampleOptions options;
    options.size_px = 64;
    options.version = version;
    WriteExampleMaterial(dir / name, options);
    files.push_back(dir / name);
  }
  const LoadedMaterial fleece = LoadMaterial(test::SharedReference() / "samples/browzwear-1.1-polartec-fleece.u3ma");
  SaveMaterial(fleece.material, fleece.base_dir, dir / "fleece/fleece.u3m");
  files.push_back(dir / "fleece/fleece.u3m");

  std::string report;
  EXPECT_EQ(RunSchemaChecker(files, dir / "log.txt", report), 0) << report;
  EXPECT_EQ(report, "");
}

}  // namespace
}  // namespace u3mscan
