// The u3m subcommands of the `u3mscan` binary: validate, convert, info, example.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "u3m/image_io.h"
#include "u3m/material.h"
#include "u3m/material_json.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

std::string Quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  out += '\'';
  return out;
}

RunResult U3mscan(const std::string& args) {
  std::string command = Quote(U3MSCAN_BINARY);
  command += ' ';
  command += args;
  command += " 2>&1";
  RunResult run;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return run;
  char buffer[4096];
  while (std::fgets(buffer, sizeof(buffer), pipe)) run.output += buffer;
  const int status = pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

// Two commands' maps from the same code on the same input: the same floats.
constexpr float kSameMapTolerance = 1e-6f;

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / ("u3mscan_cli_" + std::string(info->name()) + "_" + NewUuid4().substr(0, 6));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ignored;
    fs::remove_all(dir_, ignored);
  }
  std::string Path(const std::string& name) const { return Quote((dir_ / name).string()); }
  // A JSON file the run wrote (fit.json, report.json), parsed.
  nlohmann::json ReadJson(const std::string& name) const {
    std::ifstream in(dir_ / name);
    return nlohmann::json::parse(in);
  }
  // `u3mscan args`, expected to exit with 0 (a failure names the command and gives its output).
  static RunResult Succeeds(const std::string& args) {
    RunResult run = U3mscan(args);
    EXPECT_EQ(run.exit_code, 0) << "u3mscan " << args << "\n" << run.output;
    return run;
  }
  // A plain weave on the oblique rig (a tilted camera) with its camera at twice the maps' 300 dpi,
  // rendered into dir_/plain; returns its capture folder, quoted for the command line.
  std::string PlainObliqueAtTwiceTheMapsDpi() const {
    Succeeds("synth --scene plain --rig oblique --size 128x128 --dpi 600 --no-calibration --format tiff -o " +
             Path("plain"));
    return Path("plain/capture");
  }
  // The largest |a - b| over every sample of two float maps (relative paths under dir_); infinity
  // when their sizes differ.
  float LargestDifference(const fs::path& a_path, const fs::path& b_path) const {
    const Image a = ReadImageFile(dir_ / a_path, PixelEncoding::kLinear), b = ReadImageFile(dir_ / b_path, PixelEncoding::kLinear);
    EXPECT_EQ(a.data().size(), b.data().size()) << a_path << " and " << b_path;
    if (a.data().size() != b.data().size()) return std::numeric_limits<float>::infinity();
    float largest = 0.0f;
    for (std::size_t i = 0; i < a.data().size(); ++i) largest = std::max(largest, std::abs(a.data()[i] - b.data()[i]));
    return largest;
  }
  fs::path dir_;
};

TEST_F(Cli, HelpListsTheU3mCommandsAndEachHasHelp) {
  const RunResult help = U3mscan("--help");
  EXPECT_EQ(help.exit_code, 0);
  for (const char* command : {"example", "validate", "convert", "info"}) {
    EXPECT_NE(help.output.find(command), std::string::npos) << command;
    const RunResult sub = U3mscan(std::string(command) + " --help");
    EXPECT_EQ(sub.exit_code, 0) << command;
    EXPECT_NE(sub.output.find("Usage"), std::string::npos) << command << ": " << sub.output;
  }
  EXPECT_NE(U3mscan("validate --help").output.find("Exit status"), std::string::npos);
}

TEST_F(Cli, ExampleWritesAValidMaterialThatInfoAndValidateRead) {
  const RunResult example = U3mscan("example -o " + Path("out") + " --size 64");
  ASSERT_EQ(example.exit_code, 0) << example.output;
  EXPECT_NE(example.output.find("valid (0 errors, 0 warnings)"), std::string::npos) << example.output;
  for (const char* file : {"out/example.u3m", "out/textures/basecolor.png", "out/textures/normal.png",
                           "out/textures/roughness.png", "out/textures/displacement.png"})
    EXPECT_TRUE(fs::exists(dir_ / file)) << file;
  // The main job runs it again and again: an earlier example is replaced, anything else is not.
  EXPECT_EQ(U3mscan("example -o " + Path("out") + " --size 64").exit_code, 0);
  fs::create_directories(dir_ / "mine");
  std::ofstream(dir_ / "mine/example.u3m") << "{}";
  EXPECT_EQ(U3mscan("example -o " + Path("mine") + " --size 64").exit_code, 2);
  const RunResult validate = U3mscan("validate " + Path("out/example.u3m"));
  EXPECT_EQ(validate.exit_code, 0) << validate.output;
  const RunResult info = U3mscan("info " + Path("out/example.u3m"));
  EXPECT_EQ(info.exit_code, 0) << info.output;
  for (const char* text : {"u3mscan example plain weave", "U3M 1.1", "front", "basecolor", "normal", "roughness",
                           "displacement", "6.4 x 6.4 mm at 254 dpi", "u3mscan"})
    EXPECT_NE(info.output.find(text), std::string::npos) << text << "\n" << info.output;
  // Package and 1.0 forms.
  EXPECT_EQ(U3mscan("example -o " + Path("pkg") + " --size 64 --package").exit_code, 0);
  EXPECT_TRUE(fs::exists(dir_ / "pkg/example.u3ma"));
  EXPECT_EQ(U3mscan("validate " + Path("pkg/example.u3ma")).exit_code, 0);
  const RunResult v10 = U3mscan("example -o " + Path("v10") + " --size 64 --schema 1.0");
  EXPECT_EQ(v10.exit_code, 0) << v10.output;
  EXPECT_NE(v10.output.find("U3M 1.0"), std::string::npos) << v10.output;
}

TEST_F(Cli, ValidateExitCodesAreZeroOneTwo) {
  ASSERT_EQ(U3mscan("example -o " + Path("ok") + " --size 64").exit_code, 0);
  // Invalid: a zone-less timestamp (readable, but breaks the schema).
  std::ifstream in(dir_ / "ok/example.u3m");
  std::stringstream text;
  text << in.rdbuf();
  std::string invalid = text.str();
  const auto pos = invalid.find("Z\",");  // end of the first timestamp
  ASSERT_NE(pos, std::string::npos);
  invalid.erase(pos, 1);
  std::ofstream(dir_ / "ok/invalid.u3m") << invalid;
  std::ofstream(dir_ / "ok/broken.u3m") << "{\"schema\": \"1.1\", \"material\": ";

  const RunResult bad = U3mscan("validate " + Path("ok/invalid.u3m"));
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("/material/created"), std::string::npos) << bad.output;
  const RunResult broken = U3mscan("validate " + Path("ok/broken.u3m") + " " + Path("ok/example.u3m"));
  EXPECT_EQ(broken.exit_code, 2) << broken.output;
  EXPECT_NE(broken.output.find("UNREADABLE"), std::string::npos) << broken.output;
  EXPECT_EQ(U3mscan("validate " + Path("ok/nothing.u3m")).exit_code, 2);
  // Malformed input: a clear message naming file and pointer, exit 2, nothing written.
  std::ofstream(dir_ / "ok/traversal.u3m")
      << std::string(text.str()).replace(text.str().find("textures/normal.png"), 19, "../../../etc/passwd");
  for (const char* name : {"ok/broken.u3m", "ok/traversal.u3m"}) {
    const RunResult convert = U3mscan("convert " + Path(name) + " " + Path("conv/out.u3ma"));
    EXPECT_EQ(convert.exit_code, 2) << name << ": " << convert.output;
    EXPECT_NE(convert.output.find(name), std::string::npos) << convert.output;
    EXPECT_FALSE(fs::exists(dir_ / "conv")) << name;
  }
  EXPECT_NE(U3mscan("convert " + Path("ok/traversal.u3m") + " " + Path("conv/out.u3m")).output.find("/normal/texture/image/path"),
            std::string::npos);
}

TEST_F(Cli, ConvertChangesVersionsAndRefusesWhatTheTargetCannotHold) {
  ASSERT_EQ(U3mscan("example -o " + Path("src") + " --size 64 --schema 1.0").exit_code, 0);
  const RunResult up = U3mscan("convert " + Path("src/example.u3m") + " " + Path("up/m.u3m") + " --schema 1.1");
  ASSERT_EQ(up.exit_code, 0) << up.output;
  EXPECT_TRUE(fs::exists(dir_ / "up/textures/normal.png"));
  const RunResult down = U3mscan("convert " + Path("up/m.u3m") + " " + Path("down/m.u3ma") + " --schema 1.0");
  ASSERT_EQ(down.exit_code, 0) << down.output;
  EXPECT_EQ(U3mscan("validate " + Path("down/m.u3ma")).exit_code, 0);
  EXPECT_NE(U3mscan("info " + Path("down/m.u3ma")).output.find("U3M 1.0"), std::string::npos);
  // The full example has physics and a preview: 1.0 cannot hold them; nothing is written.
  ASSERT_EQ(U3mscan("example -o " + Path("full") + " --size 64").exit_code, 0);
  const RunResult refused = U3mscan("convert " + Path("full/example.u3m") + " " + Path("no/m.u3m") + " --schema 1.0");
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("/material/physics"), std::string::npos) << refused.output;
  EXPECT_FALSE(fs::exists(dir_ / "no"));
  // An existing output is not replaced without --force.
  EXPECT_EQ(U3mscan("convert " + Path("up/m.u3m") + " " + Path("up/m.u3m")).exit_code, 2);
  EXPECT_EQ(U3mscan("convert " + Path("up/m.u3m") + " " + Path("up/m.u3m") + " --force").exit_code, 0);
}

TEST_F(Cli, ConvertKeepsForeignCustomSectionsOfTheSamples) {
  const fs::path shared = fs::path(U3MSCAN_SHARED_DIR) / "reference/u3m/samples";
  if (!fs::exists(shared)) GTEST_SKIP() << "no " << shared << ": sample conversion SKIPPED";
  const RunResult run = U3mscan("convert " + Quote((shared / "browzwear-1.1-polartec-fleece.u3ma").string()) + " " +
                          Path("f/fleece.u3m"));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(U3mscan("validate " + Path("f/fleece.u3m")).exit_code, 0);
  const RunResult to10 = U3mscan("convert " + Quote((shared / "browzwear-1.1-polartec-fleece.u3ma").string()) + " " +
                           Path("g/fleece.u3m") + " --schema 1.0");
  EXPECT_EQ(to10.exit_code, 2) << to10.output;  // physics and preview
  std::ifstream written(dir_ / "f/fleece.u3m");
  std::stringstream text;
  text << written.rdbuf();
  EXPECT_NE(text.str().find("\"height\": 63.838661193847659"), std::string::npos);  // Browzwear's own spelling
  const JsonValue custom = *ParseJson(text.str(), "out").Find("custom");
  ASSERT_TRUE(custom.is_object());
  EXPECT_EQ(custom.members().size(), 2u);
  EXPECT_EQ(custom.members()[0].first, "Browzwear");
  EXPECT_EQ(custom.members()[1].first, "Vizoo");
}

// `fit --follow-fibres` on a satin whose stretch the near rig's 16 lights measure: the rotation
// is then each pixel's (a texture with more values than the fit has clusters); without the option
// one turn per cluster.
TEST_F(Cli, FitFollowsTheFibresWhenAsked) {
  ASSERT_EQ(U3mscan("synth --scene satin --rig near --size 80x64 --no-calibration --format tiff -o " + Path("satin")).exit_code, 0);
  auto distinct_turns = [&](const std::string& out) {
    const Image turns = ReadImageFile(dir_ / out / "maps" / "anisotropy_rotation.exr", PixelEncoding::kLinear);
    return std::set<float>(turns.plane(0).begin(), turns.plane(0).end()).size();
  };
  const RunResult with = U3mscan("fit " + Path("satin/capture") + " -o " + Path("with") + " --preset fast --follow-fibres");
  ASSERT_EQ(with.exit_code, 0) << with.output;
  ASSERT_TRUE(fs::exists(dir_ / "with/maps/anisotropy_rotation.exr")) << with.output;
  const RunResult without = U3mscan("fit " + Path("satin/capture") + " -o " + Path("without") + " --preset fast");
  ASSERT_EQ(without.exit_code, 0) << without.output;
  auto clusters = [&](const std::string& out) { return ReadJson(out + "/fit.json")["clusters"].size(); };
  EXPECT_GT(distinct_turns("with"), clusters("with"));
  if (fs::exists(dir_ / "without/maps/anisotropy_rotation.exr")) {
    EXPECT_LE(distinct_turns("without"), clusters("without"));
  }
}

// `fit --one-pixel-prior`: every cluster that measures roughness regularises its pixels with the
// one prior std; by default fit.json says the prior came from the clusters' own spread. `process`
// takes the same switch and reports it.
TEST_F(Cli, FitAndProcessTakeOnePixelPriorWhenAsked) {
  ASSERT_EQ(U3mscan("synth --scene plain --rig near --size 48x48 --no-calibration --format tiff -o " + Path("plain")).exit_code, 0);
  const RunResult one = U3mscan("fit " + Path("plain/capture") + " -o " + Path("one") + " --one-pixel-prior");
  ASSERT_EQ(one.exit_code, 0) << one.output;
  const RunResult own = U3mscan("fit " + Path("plain/capture") + " -o " + Path("own"));
  ASSERT_EQ(own.exit_code, 0) << own.output;
  const nlohmann::json with_one = ReadJson("one/fit.json"), with_own = ReadJson("own/fit.json");
  EXPECT_FALSE(with_one["options"]["pixel_prior_from_samples"].get<bool>());
  EXPECT_TRUE(with_own["options"]["pixel_prior_from_samples"].get<bool>());
  const double one_prior = with_one["options"]["pixel_prior_std"].get<double>();
  int measuring = 0;
  for (const nlohmann::json& cluster : with_one["clusters"]) {
    if (!cluster["parameters"]["roughness"]["measured"].get<bool>()) continue;
    ++measuring;
    EXPECT_EQ(cluster["pixel_prior_std"]["roughness"].get<double>(), one_prior) << cluster.dump();
  }
  EXPECT_GT(measuring, 0) << "the plain weave's roughness is measured on the near rig";
  // `process` takes the same switch and says which prior it ran with in report.json.
  auto process_prior = [&](const std::string& out, const std::string& extra) {
    const RunResult run = U3mscan("process " + Path("plain/capture") + " -o " + Path(out) + " --preset fast" + extra);
    EXPECT_EQ(run.exit_code, 0) << run.output;
    return ReadJson(out + "/report.json")["options"]["pixel_prior_from_samples"];
  };
  EXPECT_EQ(process_prior("process_one", " --one-pixel-prior"), false);
  EXPECT_EQ(process_prior("process_own", ""), true);
}

// `fit --normal-then-lobe` and `process --normal-then-lobe`: each pixel's normal and lobe refined
// one after the other; by default together, and fit.json and report.json say which.
TEST_F(Cli, FitAndProcessRefineTheNormalWithTheLobeUnlessAsked) {
  ASSERT_EQ(U3mscan("synth --scene plain --rig near --size 48x48 --no-calibration --format tiff -o " + Path("plain")).exit_code, 0);
  auto fit_option = [&](const std::string& out, const std::string& extra) {
    const RunResult run = U3mscan("fit " + Path("plain/capture") + " -o " + Path(out) + extra);
    EXPECT_EQ(run.exit_code, 0) << run.output;
    return ReadJson(out + "/fit.json")["options"]["refine_normal_with_lobe"];
  };
  EXPECT_EQ(fit_option("apart", " --normal-then-lobe"), false);
  EXPECT_EQ(fit_option("together", ""), true);
  const RunResult run = U3mscan("process " + Path("plain/capture") + " -o " + Path("process_apart") +
                                " --preset fast --normal-then-lobe");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(ReadJson("process_apart/report.json")["options"]["refine_normal_with_lobe"], false);
}

// `fit` runs what `process` runs before its fit (pipeline/side_run.h): on a tilted camera at twice
// the maps' dpi, the relief registration and the finer grid's facets, so both write the same
// parameter maps; in bands past --max-memory; with the held-out lights' error in fit.json. Before
// side_run.h, `fit` solved one normal a map pixel on the plane and its maps differed.
TEST_F(Cli, FitRunsWhatProcessRunsBeforeItsFit) {
  const std::string capture = PlainObliqueAtTwiceTheMapsDpi();
  const RunResult fit = Succeeds("fit " + capture + " -o " + Path("fit") + " --preset fast --dpi 300");
  Succeeds("process " + capture + " -o " + Path("process") + " --preset fast --dpi 300 --debug-maps");
  ASSERT_FALSE(HasFailure());
  const nlohmann::json fit_json = ReadJson("fit/fit.json");
  EXPECT_EQ(fit_json["run"]["ps_supersample"], 2) << fit_json["run"].dump();
  EXPECT_EQ(fit_json["run"]["bands"], 1) << fit_json["run"].dump();
  EXPECT_NE(fit.output.find("relief registration"), std::string::npos) << fit.output;
  EXPECT_NE(fit.output.find("finer grid's facets"), std::string::npos) << fit.output;
  int compared = 0;
  for (const char* map : {"base_color", "roughness", "specular", "sheen", "sheen_tint"}) {
    const fs::path from_fit = fs::path("fit") / "maps" / (std::string(map) + ".exr");
    const fs::path from_process = fs::path("process") / "maps" / (std::string(map) + ".exr");
    ASSERT_EQ(fs::exists(dir_ / from_fit), fs::exists(dir_ / from_process)) << map;  // measured by both or neither
    if (!fs::exists(dir_ / from_fit)) continue;
    EXPECT_LE(LargestDifference(from_fit, from_process), kSameMapTolerance) << map;
    ++compared;
  }
  EXPECT_GE(compared, 3) << "the oblique rig measures the base colour and roughness, specular and sheen";
  // A budget below the stack's: bands; the held-out lights' error in fit.json.
  const double stack_gib = ReadJson("process/report.json")["options"]["tiles_front"]["stack_gib"].get<double>();
  const RunResult banded = Succeeds("fit " + capture + " -o " + Path("banded") + " --preset fast --dpi 300 --max-memory " +
                                    std::to_string(stack_gib / 2.5) + " --hold-out-lights L03");
  ASSERT_FALSE(HasFailure());
  const nlohmann::json banded_json = ReadJson("banded/fit.json");
  EXPECT_GT(banded_json["run"]["bands"].get<int>(), 1) << banded_json["run"].dump();
  ASSERT_TRUE(banded_json.contains("held_out_lights")) << banded.output;
  EXPECT_EQ(banded_json["held_out_lights"]["lights"].size(), 1u);
  EXPECT_EQ(banded_json["held_out_lights"]["lights"][0]["id"], "L03");
  const double error = banded_json["held_out_lights"]["relative_rmse"].get<double>();
  EXPECT_TRUE(error > 0.0 && error < 1.0) << error;
  // A light the capture does not have: refused with the option named, exit 2, nothing written.
  const RunResult unknown = U3mscan("fit " + capture + " -o " + Path("unknown") + " --preset fast --dpi 300 --hold-out-lights L99");
  EXPECT_EQ(unknown.exit_code, 2) << unknown.output;
  EXPECT_NE(unknown.output.find("--hold-out-lights"), std::string::npos) << unknown.output;
  EXPECT_FALSE(fs::exists(dir_ / "unknown"));
}

// `reconstruct` on a capture with a tilted camera takes the normals from the most vertical view
// alone, as `process` does (pipeline/relief_registration.h), so the normals and heights it writes
// are those `process --debug-maps --no-top-view-refinement` writes for a tilted capture (`process`
// refines them against the top view once its fit knows the lobes, which `reconstruct` does not
// fit: pipeline/top_view_normals.h). Before, it solved every view on the face's plane and the
// tilted view's shifted relief and lobes leaned the normals (this capture: 11.2 deg mean normal
// error against process's 1.91, measured 2026-12-07; docs/reconstruction.md, CLI).
TEST_F(Cli, ReconstructTakesATiltedCapturesNormalsFromTheTopView) {
  const std::string capture = PlainObliqueAtTwiceTheMapsDpi();
  Succeeds("reconstruct " + capture + " -o " + Path("reconstruct") + " --dpi 300");
  Succeeds("process " + capture + " -o " + Path("process") + " --dpi 300 --debug-maps --no-top-view-refinement");
  ASSERT_FALSE(HasFailure());
  bool registered = false;  // the capture's tilted view: `process` registers it on the relief
  const nlohmann::json process_report = ReadJson("process/report.json");
  for (const nlohmann::json& step : process_report["steps"]) {
    registered = registered || step["name"].get<std::string>().rfind("relief registration", 0) == 0;
  }
  ASSERT_TRUE(registered);
  for (const char* map : {"normal", "height"}) {
    const std::string file = std::string(map) + ".exr";
    const float largest = LargestDifference(fs::path("reconstruct") / "maps" / file, fs::path("process") / "maps" / file);
    std::cout << "[ MEASURED ] " << map << ": largest difference from process's " << largest << "\n";
    EXPECT_LE(largest, kSameMapTolerance) << map;
  }
}

TEST_F(Cli, SynthBallAndBenchDiligentRefuseBadArgumentsAndWriteNothing) {
  const RunResult too_big = U3mscan("synth-ball --size 96x80 --radius 60 -o " + Path("ball"));
  EXPECT_EQ(too_big.exit_code, 2) << too_big.output;
  EXPECT_NE(too_big.output.find("--radius"), std::string::npos) << too_big.output;
  EXPECT_FALSE(fs::exists(dir_ / "ball"));
  const RunResult no_objects = U3mscan("bench --diligent " + Path("nothing") + " -o " + Path("out"));
  EXPECT_EQ(no_objects.exit_code, 2) << no_objects.output;
  EXPECT_NE(no_objects.output.find("light_directions.txt"), std::string::npos) << no_objects.output;
  EXPECT_FALSE(fs::exists(dir_ / "out"));
  // The synthetic matrix's options do not go with --diligent.
  EXPECT_EQ(U3mscan("bench --diligent " + Path("nothing") + " --quick -o " + Path("out")).exit_code, 2);
  // A small ball and its benchmark: every method in the table.
  ASSERT_EQ(U3mscan("synth-ball --size 48x40 --radius 16 --lights 12 -o " + Path("ball")).exit_code, 0);
  const RunResult bench = U3mscan("bench --diligent " + Path("ball") + " -o " + Path("out"));
  ASSERT_EQ(bench.exit_code, 0) << bench.output;
  std::ifstream md(dir_ / "out/diligent.md");
  std::stringstream text;
  text << md.rdbuf();
  for (const char* method : {"| ls | lambert |", "| ls | burley |", "| robust | lambert |", "| robust | burley |"}) {
    EXPECT_NE(text.str().find(method), std::string::npos) << method << "\n" << text.str();
  }
}

}  // namespace
}  // namespace u3mscan
