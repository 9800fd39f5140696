#include "pipeline/batch.h"

#include <gtest/gtest.h>

#include <fstream>
#include <stdexcept>

#include "core/error.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

class BatchTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("u3mscan_batch_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  void TearDown() override { fs::remove_all(root_); }
  fs::path MakeCapture(const std::string& name) {
    const fs::path dir = root_ / "in" / name;
    fs::create_directories(dir);
    std::ofstream(dir / "capture.json") << "{}";
    return dir;
  }
  fs::path root_;
};

TEST_F(BatchTest, SingleCaptureWritesStraightIntoOut) {
  const fs::path capture = MakeCapture("denim 01");
  const auto jobs = PlanBatch({capture}, root_ / "out");
  ASSERT_EQ(jobs.size(), 1u);
  EXPECT_EQ(jobs[0].out_dir, root_ / "out");
  EXPECT_EQ(jobs[0].name, "denim_01");
}

TEST_F(BatchTest, FolderOfCapturesExpandsSortedIntoSubfolders) {
  MakeCapture("b");
  MakeCapture("a");
  fs::create_directories(root_ / "in" / "not-a-capture");
  const auto jobs = PlanBatch({root_ / "in"}, root_ / "out");
  ASSERT_EQ(jobs.size(), 2u);
  EXPECT_EQ(jobs[0].name, "a");
  EXPECT_EQ(jobs[1].out_dir, root_ / "out" / "b");
}

TEST_F(BatchTest, RejectsInputsThatAreNotCaptures) {
  fs::create_directories(root_ / "empty");
  EXPECT_THROW(PlanBatch({root_ / "empty"}, root_ / "out"), InputError);
  EXPECT_THROW(PlanBatch({root_ / "missing"}, root_ / "out"), InputError);
}

TEST_F(BatchTest, OneFailingCaptureDoesNotStopTheOthers) {
  MakeCapture("good1");
  MakeCapture("broken");
  MakeCapture("good2");
  const auto jobs = PlanBatch({root_ / "in"}, root_ / "out");
  std::vector<std::string> processed;
  BatchOptions options;
  const auto outcomes = RunBatch(
      jobs,
      [&](const CaptureJob& job) {
        if (job.name == "broken") throw InputError("capture.json", "/frames/0/file", "an existing frame file");
        processed.push_back(job.name);
      },
      nullptr, options);
  EXPECT_EQ(processed.size(), 2u);
  EXPECT_EQ(BatchExitCode(outcomes), 1);
  const std::string summary = FormatBatchSummary(outcomes);
  EXPECT_NE(summary.find("FAILED"), std::string::npos);
  EXPECT_NE(summary.find("/frames/0/file"), std::string::npos);
  EXPECT_NE(summary.find("2 processed, 0 skipped, 1 failed"), std::string::npos);
}

TEST_F(BatchTest, SkipExistingSkipsCompleteOutputs) {
  MakeCapture("done");
  MakeCapture("todo");
  const auto jobs = PlanBatch({root_ / "in"}, root_ / "out");
  int runs = 0;
  BatchOptions options;
  options.skip_existing = true;
  options.parallel_captures = 2;
  const auto outcomes = RunBatch(
      jobs, [&](const CaptureJob&) { ++runs; }, [](const CaptureJob& job) { return job.name == "done"; }, options);
  EXPECT_EQ(runs, 1);
  EXPECT_EQ(BatchExitCode(outcomes), 0);
  EXPECT_TRUE(outcomes[0].skipped);
}

TEST(SafeMaterialName, KeepsOnlyPortableCharacters) {
  EXPECT_EQ(SafeMaterialName("../etc/passwd"), "_etc_passwd");
  EXPECT_EQ(SafeMaterialName(".."), "material");
  EXPECT_EQ(SafeMaterialName("Velvet Rot (2)"), "Velvet_Rot__2_");
}

}  // namespace
}  // namespace u3mscan
