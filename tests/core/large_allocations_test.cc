// core/large_allocations.h: a freed large buffer stays in the heap for the next one.
#include "core/large_allocations.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace u3mscan {
namespace {

// About one frame of a 9 MP fine band (3 float planes), well above glibc's default threshold.
constexpr std::size_t kLargeBytes = std::size_t{100} << 20;

TEST(LargeAllocations, AFreedLargeBufferStaysInTheHeapForTheNext) {
#if !defined(__GLIBC__)
  GTEST_SKIP() << "KeepLargeAllocationsInTheHeap tunes glibc's allocator only";
#else
  ASSERT_TRUE(KeepLargeAllocationsInTheHeap());
  const struct mallinfo2 before = mallinfo2();
  {
    std::vector<float> buffer(kLargeBytes / sizeof(float), 1.0f);
    const struct mallinfo2 during = mallinfo2();
    // Its own mapping would show in hblkhd (bytes in mmapped blocks); the heap's arena holds it.
    EXPECT_EQ(during.hblkhd, before.hblkhd) << "the buffer was given its own mapping";
    EXPECT_GE(during.arena, before.arena + kLargeBytes);
  }
  // Freed, it is kept as free heap memory (fordblks) instead of being unmapped.
  EXPECT_GE(mallinfo2().fordblks, kLargeBytes);
#endif
}

}  // namespace
}  // namespace u3mscan
