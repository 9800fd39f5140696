#include "core/large_allocations.h"

#include <cstdlib>  // defines __GLIBC__ on glibc (through <features.h>), tested below

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace u3mscan {

namespace {
// Allocations up to this size come from the heap (bytes); larger ones still get their own mapping.
constexpr int kMmapThresholdBytes = 1 << 30;
// Free memory kept at the heap's top before it is returned to the system (bytes).
constexpr int kTrimThresholdBytes = 1 << 30;
}  // namespace

bool KeepLargeAllocationsInTheHeap() {
#if defined(__GLIBC__)
  // mallopt returns 1 on success. Setting either turns off glibc's dynamic threshold adjustment.
  const bool mmap_set = mallopt(M_MMAP_THRESHOLD, kMmapThresholdBytes) == 1;
  const bool trim_set = mallopt(M_TRIM_THRESHOLD, kTrimThresholdBytes) == 1;
  return mmap_set && trim_set;
#else
  return false;
#endif
}

}  // namespace u3mscan
