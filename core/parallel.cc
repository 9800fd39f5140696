#include "core/parallel.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace u3mscan {
namespace {
std::atomic<int> g_threads{0};
}

void SetThreadCount(int threads) { g_threads = std::max(0, threads); }

int GetThreadCount() {
  const int set = g_threads.load();
  if (set > 0) return set;
  return std::max(1u, std::thread::hardware_concurrency());
}

void ParallelFor(std::size_t count, const std::function<void(std::size_t, std::size_t)>& body) {
  if (count == 0) return;
  const std::size_t workers = std::min<std::size_t>(GetThreadCount(), count);
  if (workers <= 1) {
    body(0, count);
    return;
  }
  // More chunks than workers balances rows of uneven cost (shadows, masked pixels).
  const std::size_t chunks = std::min<std::size_t>(count, workers * 8);
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto run = [&] {
    for (;;) {
      const std::size_t chunk = next.fetch_add(1);
      if (chunk >= chunks) return;
      const std::size_t begin = count * chunk / chunks;
      const std::size_t end = count * (chunk + 1) / chunks;
      try {
        body(begin, end);
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(workers - 1);
  for (std::size_t i = 1; i < workers; ++i) threads.emplace_back(run);
  run();
  for (auto& t : threads) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace u3mscan
