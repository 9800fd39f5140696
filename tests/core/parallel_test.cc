#include "core/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace u3mscan {
namespace {

TEST(ParallelFor, CoversEveryIndexExactlyOnce) {
  SetThreadCount(4);
  std::vector<std::atomic<int>> hits(1001);
  ParallelFor(hits.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) hits[i]++;
  });
  for (std::size_t i = 0; i < hits.size(); ++i) ASSERT_EQ(hits[i].load(), 1) << i;
  SetThreadCount(0);
}

TEST(ParallelFor, RethrowsWorkerExceptions) {
  SetThreadCount(2);
  EXPECT_THROW(ParallelFor(100, [](std::size_t begin, std::size_t) {
                 if (begin > 0) throw std::runtime_error("boom");
               }),
               std::runtime_error);
  SetThreadCount(0);
}

TEST(ParallelFor, ZeroCountCallsNothing) {
  bool called = false;
  ParallelFor(0, [&](std::size_t, std::size_t) { called = true; });
  EXPECT_FALSE(called);
}

}  // namespace
}  // namespace u3mscan
