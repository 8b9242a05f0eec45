#include "tracking/reconnecting_source.h"

#include <algorithm>
#include <exception>
#include <string>
#include <thread>

#include "calib/core/log.h"

namespace nerfar {
namespace {

using Clock = std::chrono::steady_clock;

class ReconnectingSource final : public FrameSource {
 public:
  ReconnectingSource(std::unique_ptr<FrameSource> source, SourceOpener reopen, ReconnectOptions options)
      : source_(std::move(source)), reopen_(std::move(reopen)), options_(options) {
    if (source_) description_ = source_->Describe();
  }

  std::string Describe() const override { return source_ ? source_->Describe() : description_ + " (reconnecting)"; }

  FrameStatus Next(Frame& frame, int timeout_ms) override {
    if (!source_ && !Reopen(timeout_ms)) return FrameStatus::kLost;
    FrameStatus status;
    try {
      status = source_->Next(frame, timeout_ms);
    } catch (const std::exception& e) {
      Drop(std::string("the source failed: ") + e.what());
      return FrameStatus::kLost;
    }
    if (status == FrameStatus::kLost) {
      error_ = source_->LastError();
      if (++lost_in_a_row_ >= options_.lost_limit) Drop("lost " + std::to_string(lost_in_a_row_) + " times in a row");
      return status;
    }
    lost_in_a_row_ = 0;
    if (status == FrameStatus::kOk) Continue(frame);
    return status;
  }

  bool SetExposure(double exposure_us) override { return source_ && source_->SetExposure(exposure_us); }
  std::string LastError() const override { return source_ ? source_->LastError() : error_; }

 private:
  void Drop(const std::string& why) {
    error_ = description_ + ": " + why + "; opening it again every " + std::to_string(options_.retry.count()) + " ms";
    LogWarning(error_);
    source_.reset();
    lost_in_a_row_ = 0;
  }

  // Waits for the next attempt (within the timeout) and makes it; true once open.
  bool Reopen(int timeout_ms) {
    const auto due = last_attempt_ + options_.retry;
    if (Clock::now() < due) {
      std::this_thread::sleep_until(std::min(due, Clock::now() + std::chrono::milliseconds(std::max(0, timeout_ms))));
      if (Clock::now() < due) return false;
    }
    last_attempt_ = Clock::now();
    try {
      source_ = reopen_();
    } catch (const std::exception& e) {
      error_ = description_ + ": cannot open it again (" + e.what() + ")";
      return false;
    }
    if (!source_) return false;
    const bool first = description_.empty();
    if (first) description_ = source_->Describe();
    reopened_ = true;
    LogInfo(description_ + (first ? ": opened" : ": opened again"));
    return true;
  }

  // Numbers and time stamps go on from the last frame delivered.
  void Continue(Frame& frame) {
    if (reopened_ && delivered_) {
      index_offset_ = last_index_ + 1 - frame.index;
      t_offset_ns_ = std::max<std::int64_t>(0, last_t_ns_ + 1 - frame.t_ns);
    }
    reopened_ = false;
    frame.index += index_offset_;
    frame.t_ns += t_offset_ns_;
    last_index_ = frame.index;
    last_t_ns_ = frame.t_ns;
    delivered_ = true;
  }

  std::unique_ptr<FrameSource> source_;
  SourceOpener reopen_;
  ReconnectOptions options_;
  std::string description_, error_;
  int lost_in_a_row_ = 0;
  Clock::time_point last_attempt_{};
  bool reopened_ = false, delivered_ = false;
  std::int64_t last_index_ = 0, last_t_ns_ = 0, index_offset_ = 0, t_offset_ns_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> ReconnectOnLoss(std::unique_ptr<FrameSource> source, SourceOpener reopen,
                                             ReconnectOptions options) {
  return std::make_unique<ReconnectingSource>(std::move(source), std::move(reopen), options);
}

}  // namespace nerfar
