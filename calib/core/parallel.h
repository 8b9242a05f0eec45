// Threads: one process-wide thread count (`--threads N`), and ParallelFor over
// oneTBB. Work is split into fixed chunks and any reduction is done by the
// caller in index order, so results never depend on the thread count.
#pragma once

#include <cstddef>
#include <functional>

namespace nerfar {

// Sets the number of worker threads for everything after it (0: all cores).
void SetThreadCount(int threads);
int ThreadCount();

// Calls body(begin, end) on disjoint chunks of [0, count) of at most `grain`
// items, possibly in parallel. The chunk boundaries depend only on count and
// grain, never on the number of threads.
void ParallelForChunks(size_t count, size_t grain, const std::function<void(size_t, size_t)>& body);

// Calls body(i) for every i in [0, count).
template <typename Body>
void ParallelFor(size_t count, Body&& body, size_t grain = 64) {
  ParallelForChunks(count, grain, [&body](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) body(i);
  });
}

}  // namespace nerfar
