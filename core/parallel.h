#pragma once
// ParallelFor: splits [0, count) into contiguous chunks over a fixed number of std::threads.
// Used for per-pixel and per-row loops; each worker gets whole rows so no per-pixel allocation or
// synchronisation happens inside the loop.

#include <cstddef>
#include <functional>

namespace u3mscan {

// Number of worker threads used by ParallelFor (default: std::thread::hardware_concurrency()).
void SetThreadCount(int threads);
int GetThreadCount();

// Calls body(begin, end) on disjoint chunks covering [0, count). Exceptions from a worker are
// rethrown on the calling thread after all workers finish.
void ParallelFor(std::size_t count, const std::function<void(std::size_t begin, std::size_t end)>& body);

}  // namespace u3mscan
