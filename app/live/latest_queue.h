// A one-slot queue between pipeline stages (capture -> tracking/render ->
// display): the producer never waits, and a slow consumer always gets the
// newest item; the items it never took are counted as dropped (Basalt's
// bounded queues, with capacity 1 because a live view only wants the latest).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>

namespace nerfar {

template <typename T>
class LatestQueue {
 public:
  void Push(T item) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (slot_.has_value()) ++dropped_;
      slot_ = std::move(item);
    }
    ready_.notify_one();
  }

  // Waits up to timeout for an item; nullopt on timeout or after Close().
  std::optional<T> Pop(std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(mutex_);
    ready_.wait_for(lock, timeout, [this] { return slot_.has_value() || closed_; });
    if (!slot_.has_value()) return std::nullopt;
    std::optional<T> item = std::move(slot_);
    slot_.reset();
    return item;
  }

  void Close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
  }

  bool closed() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return closed_;
  }

  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::optional<T> slot_;
  bool closed_ = false;
  std::uint64_t dropped_ = 0;
};

}  // namespace nerfar
