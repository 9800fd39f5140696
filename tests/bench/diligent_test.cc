// The DiLiGenT-format objects of `u3mscan bench --diligent`: the synthetic ball written by
// datasets_synthetic/diligent_ball.h reads back as written, the methods recover its normals, and a
// bad folder is an InputError naming the file, the line and what was expected, with nothing written.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "bench/diligent.h"
#include "core/error.h"
#include "core/image.h"
#include "datasets_synthetic/diligent_ball.h"
#include "tests/support/temp_dir.h"
#include "u3m/image_io.h"

namespace u3mscan::bench {
namespace {

namespace fs = std::filesystem;

constexpr double kTextRoundTrip = 1e-8;  // %.9g in the text files
// Noise-free ball without a specular lobe (Burley's diffuse alone): the robust solve with the
// Burley model recovers it (measured 0.04 deg mean).
constexpr double kNoiseFreeDiffuseBallToleranceDeg = 0.1;
// Glossy ball with noise and clipped highlights: the robust solve leaves the highlights out
// (measured 0.60 deg mean), least squares does not (5.8 deg).
constexpr double kGlossyBallRobustToleranceDeg = 1.0;
constexpr double kLeastSquaresOverRobustAtLeast = 3.0;

synthetic::DiLiGenTBallOptions SmallBall() {
  synthetic::DiLiGenTBallOptions o;
  o.width = 96;
  o.height = 80;
  o.radius_px = 36;
  o.lights = 24;
  return o;
}

const DiLiGenTRun& Method(const std::vector<DiLiGenTRun>& runs, const std::string& solver, const std::string& diffuse) {
  for (const DiLiGenTRun& r : runs) {
    if (r.solver == solver && r.diffuse_model == diffuse) return r;
  }
  throw std::runtime_error("no run " + solver + "/" + diffuse);
}

void WriteText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

// An InputError from reading `dir`, or a failure.
InputError ReadError(const fs::path& dir) {
  try {
    ReadDiLiGenTObject(dir);
  } catch (const InputError& e) {
    return e;
  }
  ADD_FAILURE() << "reading " << dir << " did not throw";
  return InputError("", "", "");
}

TEST(DiLiGenT, TheSyntheticBallReadsBackAsWritten) {
  test::TempDir dir;
  const synthetic::DiLiGenTBall ball = synthetic::WriteDiLiGenTBall(dir / "ballPNG", SmallBall());
  ASSERT_EQ(FindDiLiGenTObjects(dir.path()), std::vector<fs::path>{dir / "ballPNG"});
  const DiLiGenTObject object = ReadDiLiGenTObject(dir / "ballPNG");
  EXPECT_EQ(object.name, "ballPNG");
  ASSERT_EQ(object.stack.lights.size(), 24u);
  ASSERT_EQ(object.stack.observations.size(), 24u);
  for (std::size_t k = 0; k < 24; ++k) {
    EXPECT_LT((object.stack.lights[k].direction_in_world - ball.light_directions[k]).norm(), kTextRoundTrip) << k;
    EXPECT_LT((object.stack.lights[k].intensity_rgb - ball.light_intensities[k]).norm(), kTextRoundTrip) << k;
  }
  // Cropped to the ball's box and a pixel around it: 72 + 2 on each axis.
  EXPECT_EQ(object.stack.grid.width, 74);
  EXPECT_EQ(object.stack.grid.height, 74);
  long long on_object = 0;
  for (std::uint8_t v : object.on_object) on_object += v;
  EXPECT_EQ(on_object, ball.object_pixels);
  EXPECT_GT(object.saturated_observations, 0) << "the brightest highlights clip at full scale";
  EXPECT_EQ(object.saturated_observations, ball.saturated_observations);
  // The centre pixel of the ball faces the camera; every observation off the mask is out of view.
  EXPECT_NEAR(object.true_normal.at(2, 37, 37), 1.0, 1e-3);
  EXPECT_EQ(object.stack.observations[0].flags[0] & kOutOfView, kOutOfView);
  // The folder is written whole or not at all: a second ball is not written over the first.
  EXPECT_THROW(synthetic::WriteDiLiGenTBall(dir / "ballPNG", SmallBall()), InputError);
  EXPECT_EQ(ReadDiLiGenTObject(dir / "ballPNG").stack.lights.size(), 24u);
}

TEST(DiLiGenT, TheRobustBurleySolveRecoversANoiseFreeDiffuseBall) {
  test::TempDir dir;
  synthetic::DiLiGenTBallOptions o = SmallBall();
  o.specular = 0.0;
  o.noise = false;
  synthetic::WriteDiLiGenTBall(dir / "ball", o);
  const auto runs = RunDiLiGenTMethods(ReadDiLiGenTObject(dir / "ball"));
  ASSERT_EQ(runs.size(), 4u);
  const DiLiGenTRun& robust = Method(runs, "robust", "burley");
  EXPECT_EQ(robust.pixels, 4060);
  EXPECT_LT(robust.mean_deg, kNoiseFreeDiffuseBallToleranceDeg);
  EXPECT_EQ(robust.ill_conditioned_pixels, 0);
}

TEST(DiLiGenT, TheRobustSolverLeavesTheHighlightsOutAndLeastSquaresDoesNot) {
  test::TempDir dir;
  synthetic::WriteDiLiGenTBall(dir / "ball", SmallBall());
  const auto runs = RunDiLiGenTBench(dir / "ball", dir / "out");
  ASSERT_EQ(runs.size(), 4u);
  const double robust = Method(runs, "robust", "lambert").mean_deg;
  const double ls = Method(runs, "ls", "lambert").mean_deg;
  EXPECT_LT(robust, kGlossyBallRobustToleranceDeg);
  EXPECT_GT(ls, kLeastSquaresOverRobustAtLeast * robust);
  // The tables: a header and one line per method.
  std::ifstream csv(dir / "out" / "diligent.csv");
  int lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_EQ(lines, 5);
  EXPECT_TRUE(fs::exists(dir / "out" / "diligent.md"));
}

TEST(DiLiGenT, ABadFolderNamesTheFileTheLineAndWhatWasExpected) {
  test::TempDir dir;
  const fs::path ball = dir / "ball";
  synthetic::WriteDiLiGenTBall(ball, SmallBall());

  {  // a light direction of two numbers
    std::ifstream in(ball / "light_directions.txt");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto second_line = text.find('\n') + 1;
    const auto third_line = text.find('\n', second_line) + 1;
    WriteText(ball / "light_directions.txt", text.substr(0, second_line) + "0.1 0.2\n" + text.substr(third_line));
    const InputError e = ReadError(ball);
    EXPECT_EQ(fs::path(e.file()).filename(), "light_directions.txt");
    EXPECT_EQ(e.field(), "line 2");
    EXPECT_NE(std::string(e.what()).find("three numbers"), std::string::npos) << e.what();
    // RunDiLiGenTBench checks every object before it writes anything.
    EXPECT_THROW(RunDiLiGenTBench(dir.path(), dir / "out"), InputError);
    EXPECT_FALSE(fs::exists(dir / "out"));
    WriteText(ball / "light_directions.txt", text);
  }
  {  // one intensity too few
    std::ifstream in(ball / "light_intensities.txt");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    WriteText(ball / "light_intensities.txt", text.substr(text.find('\n') + 1));
    const InputError e = ReadError(ball);
    EXPECT_EQ(fs::path(e.file()).filename(), "light_intensities.txt");
    EXPECT_NE(std::string(e.what()).find("one line per image of filenames.txt (24), got 23"), std::string::npos) << e.what();
    WriteText(ball / "light_intensities.txt", text);
  }
  {  // an image of another size than the mask
    WriteImageFile(Image(40, 30, 3, 0.5f), ball / "007.png", ImageWriteOptions{});
    const InputError e = ReadError(ball);
    EXPECT_EQ(fs::path(e.file()).filename(), "007.png");
    EXPECT_NE(std::string(e.what()).find("96 x 80 pixels like mask.png"), std::string::npos) << e.what();
  }
  {  // the truth only as MATLAB's .mat: the message says how to convert it
    fs::rename(ball / "Normal_gt.txt", ball / "Normal_gt.mat");
    const InputError e = ReadError(ball);
    EXPECT_EQ(fs::path(e.file()).filename(), "Normal_gt.txt");
    EXPECT_NE(std::string(e.what()).find("scipy.io.loadmat"), std::string::npos) << e.what();
  }
  EXPECT_THROW(FindDiLiGenTObjects(dir / "ball" / "nothing_here"), InputError);
}

}  // namespace
}  // namespace u3mscan::bench
