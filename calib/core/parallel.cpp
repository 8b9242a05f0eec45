#include "calib/core/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <memory>
#include <mutex>
#include <thread>

namespace nerfar {
namespace {
std::mutex g_mutex;
std::unique_ptr<tbb::global_control> g_control;
int g_threads = 0;
}  // namespace

void SetThreadCount(int threads) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_threads = threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency());
  if (g_threads < 1) g_threads = 1;
  g_control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<size_t>(g_threads));
}

int ThreadCount() {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (g_threads > 0) return g_threads;
  return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

void ParallelForChunks(size_t count, size_t grain, const std::function<void(size_t, size_t)>& body) {
  if (count == 0) return;
  if (grain == 0) grain = 1;
  const size_t chunks = (count + grain - 1) / grain;
  if (chunks == 1) {
    body(0, count);
    return;
  }
  // Chunks of exactly `grain` items (the last one shorter), scheduled by TBB.
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, chunks, 1),
      [&](const tbb::blocked_range<size_t>& range) {
        for (size_t chunk = range.begin(); chunk != range.end(); ++chunk) {
          const size_t begin = chunk * grain;
          const size_t end = begin + grain < count ? begin + grain : count;
          body(begin, end);
        }
      },
      tbb::simple_partitioner());
}

}  // namespace nerfar
