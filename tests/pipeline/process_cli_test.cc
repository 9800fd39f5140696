// The `u3mscan process` command as an operator and a batch scheduler use it: exit codes, batches
// with a broken capture, reproducible reruns, resumable batches, kills midway, GNU parallel.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "tests/support/bump_scene.h"
#include "reconstruction/relief_levelling.h"
#include "u3m/image_io.h"
#include "u3m/validate.h"

extern char** environ;

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Runs a shell command line; returns its exit status (or 128 + signal).
int RunShell(const std::string& command) {
  const int status = std::system((command + " > /dev/null 2>&1").c_str());
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

// Single-quoted for /bin/sh (built by appending: GCC 12 warns falsely, -Wrestrict, on "'" + s + "'").
std::string Quote(const fs::path& path) {
  std::string quoted = "'";
  quoted += path.string();
  quoted += "'";
  return quoted;
}

class ProcessCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // One folder per process: ctest runs every test of this suite in its own process, in parallel.
    root_ = fs::temp_directory_path() / ("u3mscan_process_cli_" + std::to_string(getpid()));
    fs::remove_all(root_);
    fs::create_directories(root_ / "captures");
    synthetic::RigOptions rig_options;
    const synthetic::Rig rig = synthetic::MakeRig("distant", rig_options);
    const auto scene = testing::BumpScene(56, 56, rig_options.pitch_mm, 0.05, 1.5);
    synthetic::CaptureOptions capture_options;
    capture_options.format = synthetic::FrameFormat::kTiff;
    for (const char* name : {"a", "b"}) {
      synthetic::WriteSyntheticCapture(scene, rig, capture_options, root_ / "synth" / name);
      fs::rename(root_ / "synth" / name / "capture", root_ / "captures" / name);
    }
    // A broken capture: its manifest names a frame file that is not there.
    fs::create_directories(root_ / "captures" / "broken");
    fs::copy(root_ / "captures" / "a" / "capture.json", root_ / "captures" / "broken" / "capture.json");
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }
  static std::string Exe() { return U3MSCAN_EXECUTABLE; }
  // `process --quiet --preset fast OPTIONS captures/a -o ROOT/OUT` (the options before the capture:
  // a list must not swallow the positional path).
  static std::string FastProcessOfA(const std::string& options, const std::string& out) {
    std::string c = Exe();
    c += " process --quiet --preset fast ";
    c += options;
    c += " ";
    c += Quote(root_ / "captures" / "a");
    c += " -o ";
    c += Quote(root_ / out);
    return c;
  }
  static fs::path root_;
};
fs::path ProcessCli::root_;

constexpr const char* kFixedId = "3f2c1a9e-8b7d-4c6e-9a5f-0123456789ab";
constexpr const char* kFixedTime = "2026-11-22T10:00:00Z";

TEST_F(ProcessCli, BadUsageExitsTwo) {
  EXPECT_EQ(RunShell(Exe() + " process"), 2);
  EXPECT_EQ(RunShell(Exe() + " process " + Quote(root_ / "captures" / "a") + " -o " + Quote(root_ / "x") + " --preset turbo"), 2);
  EXPECT_FALSE(fs::exists(root_ / "x"));
}

TEST_F(ProcessCli, BrokenCaptureIsReportedAndTheOthersFinish) {
  const fs::path out = root_ / "batch";
  EXPECT_EQ(RunShell(Exe() + " process --quiet --preset fast " + Quote(root_ / "captures") + " -o " + Quote(out)), 1);
  EXPECT_TRUE(fs::exists(out / "a" / "a.u3m"));
  EXPECT_TRUE(fs::exists(out / "b" / "b.u3m"));
  EXPECT_FALSE(fs::exists(out / "broken" / "broken.u3m"));
  EXPECT_FALSE(fs::exists(out / "broken" / "report.json")) << "bad input writes no partial output";
  EXPECT_TRUE(ValidateMaterialFile(out / "a" / "a.u3m").valid());
}

TEST_F(ProcessCli, RerunWithFixedIdAndTimeWritesTheSameMaterial) {
  const std::string common = " process --quiet --preset fast --id " + std::string(kFixedId) + " --created " + kFixedTime + " " +
                             Quote(root_ / "captures" / "a");
  ASSERT_EQ(RunShell(Exe() + common + " -o " + Quote(root_ / "run1")), 0);
  ASSERT_EQ(RunShell(Exe() + common + " -o " + Quote(root_ / "run2")), 0);
  EXPECT_EQ(ReadFile(root_ / "run1" / "a.u3m"), ReadFile(root_ / "run2" / "a.u3m"));
  for (const auto& entry : fs::directory_iterator(root_ / "run1" / "textures")) {
    EXPECT_EQ(ReadFile(entry.path()), ReadFile(root_ / "run2" / "textures" / entry.path().filename()))
        << entry.path().filename();
  }
}

TEST_F(ProcessCli, HoldOutLightsAreParsedAndTheirErrorIsReported) {
  // `process --quiet --preset fast --hold-out-lights IDS captures/a -o OUT` (the list before the
  // capture: it must not swallow the positional path).
  auto command = [&](const std::string& ids, const std::string& out) {
    return FastProcessOfA("--hold-out-lights " + ids, out);
  };
  ASSERT_EQ(RunShell(command("L02,L05", "held_out")), 0);
  std::ifstream in(root_ / "held_out" / "report.json");
  const nlohmann::json report = nlohmann::json::parse(in);
  EXPECT_EQ(report["options"]["hold_out_lights"], nlohmann::json::array({"L02", "L05"}));
  const nlohmann::json& held = report["quality"]["front"]["held_out_lights"];
  ASSERT_EQ(held["lights"].size(), 2u) << report["quality"].dump();
  EXPECT_EQ(held["lights"][0]["id"], "L02");
  EXPECT_EQ(held["lights"][1]["id"], "L05");
  EXPECT_GE(held["relative_rmse"].get<double>(), 0.0);
  // The same light twice, or an empty id, is bad usage: exit 2, nothing written.
  for (const char* ids : {"L02,L02", "L02,"}) {
    EXPECT_EQ(RunShell(command(ids, "held_bad_usage")), 2) << ids;
    EXPECT_FALSE(fs::exists(root_ / "held_bad_usage")) << ids;
  }
  // A light the capture does not have: that capture fails (exit 1), nothing written for it.
  EXPECT_EQ(RunShell(command("L42", "held_unknown")), 1);
  EXPECT_FALSE(fs::exists(root_ / "held_unknown" / "report.json"));
  EXPECT_FALSE(fs::exists(root_ / "held_unknown" / "a.u3m"));
}

TEST_F(ProcessCli, PackageAndSchemaOptions) {
  ASSERT_EQ(RunShell(Exe() + " process --quiet --preset fast --package --schema 1.1 " + Quote(root_ / "captures" / "b") +
                " -o " + Quote(root_ / "pkg")),
            0);
  const fs::path package = root_ / "pkg" / "b.u3ma";
  ASSERT_TRUE(fs::exists(package));
  const ValidationReport report = ValidateMaterialFile(package);
  EXPECT_TRUE(report.valid());
  EXPECT_EQ(report.version, SchemaVersion::k1_1);
}

TEST_F(ProcessCli, WrittenFilesPassTheOfficialSchemas) {
  const fs::path schemas = fs::path(U3MSCAN_SHARED_DIR) / "reference" / "u3m";
  if (!fs::exists(schemas / "1.1" / "u3m_schema.json")) {
    GTEST_SKIP() << "official schemas not found under " << schemas << ": schema validation SKIPPED";
  }
  if (std::string(U3MSCAN_SYSTEM_PYTHON).empty()) GTEST_SKIP() << "no system python3: schema validation SKIPPED";
  for (const char* schema : {"auto", "1.0", "1.1"}) {
    const fs::path out = root_ / (std::string("schema_") + schema);
    ASSERT_EQ(RunShell(Exe() + " process --quiet --preset fast --schema " + schema + " " + Quote(root_ / "captures" / "a") +
                       " -o " + Quote(out)),
              0);
    EXPECT_EQ(RunShell(Quote(U3MSCAN_SYSTEM_PYTHON) + " " + Quote(U3MSCAN_SCHEMA_CHECKER) + " " + Quote(schemas) + " " +
                       Quote(out / "a.u3m")),
              0)
        << "schema " << schema << ": run " << U3MSCAN_SCHEMA_CHECKER << " on " << out / "a.u3m" << " for details";
  }
  EXPECT_NE(ReadFile(root_ / "schema_auto" / "a.u3m").find("\"schema\": \"1.0\""), std::string::npos)
      << "auto writes the lowest version that holds the content";
}

TEST_F(ProcessCli, SkipExistingResumesABatch) {
  const fs::path out = root_ / "resume";
  const std::string command = Exe() + " process --quiet --preset fast " + Quote(root_ / "captures" / "a") + " " +
                              Quote(root_ / "captures" / "b") + " -o " + Quote(out);
  ASSERT_EQ(RunShell(command), 0);
  const auto stamp = fs::last_write_time(out / "a" / "a.u3m");
  fs::remove(out / "b" / "report.json");  // as if the run had been killed before b finished
  ASSERT_EQ(RunShell(command + " --skip-existing"), 0);
  EXPECT_EQ(fs::last_write_time(out / "a" / "a.u3m"), stamp) << "complete output is not redone";
  EXPECT_TRUE(fs::exists(out / "b" / "report.json"));
}

TEST_F(ProcessCli, KilledMidwayLeavesNoPartialMaterial) {
  // Kill the process at several points of its run; whatever is left is either a complete material
  // (report.json written last says ok and the U3M validates) or no material at all.
  for (int delay_ms : {50, 200, 400, 700, 1000}) {
    const fs::path out = root_ / ("killed_" + std::to_string(delay_ms));
    const std::string capture = (root_ / "captures" / "a").string();
    const std::string out_arg = out.string();
    std::vector<char*> argv = {const_cast<char*>(U3MSCAN_EXECUTABLE), const_cast<char*>("process"),
                               const_cast<char*>("--quiet"), const_cast<char*>(capture.c_str()),
                               const_cast<char*>("-o"), const_cast<char*>(out_arg.c_str()), nullptr};
    pid_t pid = 0;
    ASSERT_EQ(posix_spawn(&pid, U3MSCAN_EXECUTABLE, nullptr, nullptr, argv.data(), environ), 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    const bool material = fs::exists(out / "a.u3m");
    if (material) {
      EXPECT_TRUE(ValidateMaterialFile(out / "a.u3m").valid()) << "killed after " << delay_ms << " ms";
    }
    if (fs::exists(out / "report.json")) {
      EXPECT_TRUE(material) << "report.json is written last";
    }
  }
}

TEST_F(ProcessCli, GnuParallelRecipeFromTheDocs) {
  if (RunShell("command -v parallel") != 0) GTEST_SKIP() << "GNU parallel is not installed (tools/install-deps.sh installs it)";
  const fs::path out = root_ / "parallel";
  // docs/batch.md: one capture per job, each into its own folder, resumable with --skip-existing.
  const std::string command = "cd " + Quote(root_ / "captures") + " && ls -d a b | parallel --will-cite -j 2 --halt never " +
                              Exe() + " process --quiet --skip-existing {} -o " + Quote(out) + "/{}";
  ASSERT_EQ(RunShell("bash -c \"" + command + "\""), 0);
  EXPECT_TRUE(ValidateMaterialFile(out / "a" / "a.u3m").valid());
  EXPECT_TRUE(ValidateMaterialFile(out / "b" / "b.u3m").valid());
}

// --ps-supersample: out of range is bad usage (exit 2, nothing written); 0 on a camera at the
// maps' dpi chooses 1 (no finer grid to solve on); `reconstruct` takes it too, and with maps at half
// the camera's dpi solves on the camera's grid and writes maps on the maps' grid.
TEST_F(ProcessCli, PsSupersampleIsCheckedAndReconstructTakesIt) {
  auto process = [&](const std::string& k, const std::string& out) { return FastProcessOfA("--ps-supersample " + k, out); };
  EXPECT_EQ(RunShell(process("6", "pss_bad")), 2);
  EXPECT_FALSE(fs::exists(root_ / "pss_bad"));
  ASSERT_EQ(RunShell(process("0", "pss_auto")), 0);
  std::ifstream in(root_ / "pss_auto" / "report.json");
  const nlohmann::json report = nlohmann::json::parse(in);
  EXPECT_EQ(report["options"]["ps_supersample"], 0);
  EXPECT_EQ(report["options"]["ps_supersample_front"], 1);

  auto reconstruct = [&](const std::string& extra, const std::string& out) {
    std::string c = Exe();
    c += " reconstruct ";
    c += Quote(root_ / "captures" / "a");
    c += " -o ";
    c += Quote(root_ / out);
    c += " --dpi 150 --solver ls ";
    c += extra;
    return c;
  };
  // The capture is at 300 dpi and the maps at 150: the default (0) takes the camera's grid, K = 2.
  ASSERT_EQ(RunShell(reconstruct("--ps-supersample 1", "rec_maps_grid")), 0);
  ASSERT_EQ(RunShell(reconstruct("--ps-supersample 2", "rec_camera_grid")), 0);
  ASSERT_EQ(RunShell(reconstruct("", "rec_default")), 0);
  EXPECT_EQ(RunShell(reconstruct("--ps-supersample 6", "rec_bad")), 2);
  const Image on_maps = ReadImageFile(root_ / "rec_maps_grid" / "maps" / "normal.exr", PixelEncoding::kLinear);
  const Image on_camera = ReadImageFile(root_ / "rec_camera_grid" / "maps" / "normal.exr", PixelEncoding::kLinear);
  const Image by_default = ReadImageFile(root_ / "rec_default" / "maps" / "normal.exr", PixelEncoding::kLinear);
  ASSERT_EQ(by_default.width(), on_camera.width());
  ASSERT_EQ(by_default.height(), on_camera.height());
  EXPECT_EQ(by_default.data(), on_camera.data()) << "the default is not the camera's grid";
  ASSERT_EQ(on_camera.width(), on_maps.width());
  ASSERT_EQ(on_camera.height(), on_maps.height());
  int not_unit = 0, differ = 0;
  for (int r = 0; r < on_camera.height(); ++r) {
    for (int c = 0; c < on_camera.width(); ++c) {
      double length2 = 0.0, diff = 0.0;
      for (int ch = 0; ch < 3; ++ch) {
        length2 += on_camera.at(ch, r, c) * on_camera.at(ch, r, c);
        diff += std::abs(on_camera.at(ch, r, c) - on_maps.at(ch, r, c));
      }
      not_unit += std::abs(std::sqrt(length2) - 1.0) > 1e-4;
      differ += diff > 1e-4;
    }
  }
  EXPECT_EQ(not_unit, 0);
  EXPECT_GT(differ, 0) << "the camera's grid gave the maps' grid normals";
}

// --level: a value out of the list is refused before anything is written; the default levels a
// plane out of the written height (the step says so) and keeps the normals as measured, `none`
// keeps the shape, and --level-normals also turns the normals: the plane run's height is the none
// run's with its plane removed, its normals the none run's, and the --level-normals run's normals
// the none run's turned by that tilt (reconstruction/relief_levelling.h; the kernel's own tests
// are ReliefLevelling.*).
TEST_F(ProcessCli, LevelIsCheckedAndTakesTheTiltOut) {
  // Heights written as float EXR from the same run but for the levelling: float32 round-off of
  // heights below a millimetre and of unit normals.
  constexpr double kSameRunToleranceMm = 1e-6;
  constexpr float kSameRunNormalTolerance = 1e-5f;
  EXPECT_EQ(RunShell(FastProcessOfA("--level cubic", "level_bad")), 2);
  EXPECT_FALSE(fs::exists(root_ / "level_bad"));
  ASSERT_EQ(RunShell(FastProcessOfA("--debug-maps", "level_plane")), 0);
  ASSERT_EQ(RunShell(FastProcessOfA("--debug-maps --level none", "level_none")), 0);
  ASSERT_EQ(RunShell(FastProcessOfA("--debug-maps --level-normals", "level_plane_normals")), 0);

  auto report_of = [&](const std::string& out) {
    std::ifstream in(root_ / out / "report.json");
    return nlohmann::json::parse(in);
  };
  auto step = [&](const std::string& out) {
    const nlohmann::json report = report_of(out);
    for (const auto& s : report["steps"]) {
      if (s["name"] == "level front") return s;
    }
    return nlohmann::json();
  };
  const nlohmann::json plane_step = step("level_plane"), none_step = step("level_none"),
                       turned_step = step("level_plane_normals");
  // The maps' pitch (the EXR files do not carry it): the slopes the normals turn by depend on it.
  const double pitch_mm = report_of("level_none")["calibration"]["grid"]["pitch_mm"].get<double>();
  ASSERT_FALSE(plane_step.is_null());
  EXPECT_TRUE(plane_step["ran"].get<bool>());
  EXPECT_NE(plane_step["reason"].get<std::string>().find("plane removed"), std::string::npos) << plane_step.dump();
  EXPECT_NE(plane_step["reason"].get<std::string>().find("normals kept"), std::string::npos) << plane_step.dump();
  ASSERT_FALSE(turned_step.is_null());
  EXPECT_NE(turned_step["reason"].get<std::string>().find("normals turned"), std::string::npos) << turned_step.dump();
  EXPECT_TRUE(report_of("level_plane_normals")["options"]["level_normals"].get<bool>());
  ASSERT_FALSE(none_step.is_null());
  EXPECT_FALSE(none_step["ran"].get<bool>());

  auto read = [&](const std::string& out, const char* map) {
    return ReadImageFile(root_ / out / "maps" / map, PixelEncoding::kLinear);
  };
  Image none_height = read("level_none", "height.exr");
  const Image none_normal = read("level_none", "normal.exr");
  Image turned_normal = none_normal;
  const Image plane_height = read("level_plane", "height.exr");
  const Image plane_normal = read("level_plane", "normal.exr");
  const Image written_turned_normal = read("level_plane_normals", "normal.exr");
  ASSERT_EQ(none_height.width(), plane_height.width());
  ASSERT_EQ(none_height.height(), plane_height.height());
  none_height.set_pitch_mm(pitch_mm);
  const reconstruction::LevellingResult tilt = reconstruction::LevelRelief(reconstruction::Levelling::kPlane, &none_height, &turned_normal);
  ASSERT_GT(tilt.weighted_pixels, 0.0);
  EXPECT_GT(tilt.peak_to_valley_mm, 0.0) << "the capture's height has some tilt to take out";
  double worst_mm = 0.0;
  float worst_kept = 0.0f, worst_turned = 0.0f, turn = 0.0f;
  for (int r = 0; r < none_height.height(); ++r) {
    for (int c = 0; c < none_height.width(); ++c) {
      worst_mm = std::max(worst_mm, std::abs(static_cast<double>(none_height.at(0, r, c)) - plane_height.at(0, r, c)));
      for (int ch = 0; ch < 3; ++ch) {
        worst_kept = std::max(worst_kept, std::abs(none_normal.at(ch, r, c) - plane_normal.at(ch, r, c)));
        worst_turned = std::max(worst_turned, std::abs(turned_normal.at(ch, r, c) - written_turned_normal.at(ch, r, c)));
        turn = std::max(turn, std::abs(turned_normal.at(ch, r, c) - none_normal.at(ch, r, c)));
      }
    }
  }
  EXPECT_LT(worst_mm, kSameRunToleranceMm);
  EXPECT_LT(worst_kept, kSameRunNormalTolerance) << "the default keeps the normals as measured";
  EXPECT_LT(worst_turned, kSameRunNormalTolerance) << "--level-normals turns them by the removed tilt";
  EXPECT_GT(turn, 10.0f * kSameRunNormalTolerance) << "the tilt turns the normals by more than round-off";
}

}  // namespace
}  // namespace u3mscan
