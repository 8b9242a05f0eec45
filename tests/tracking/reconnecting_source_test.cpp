// ReconnectOnLoss (tracking/reconnecting_source.h): a source that throws or
// stays lost is opened again and its frames go on with numbers and time
// stamps that keep counting; a source that ends ends. The wrapped sources are
// scripted here: each call to Next() does what its script says.
#include "tracking/reconnecting_source.h"

#include <gtest/gtest.h>

#include <deque>
#include <memory>
#include <stdexcept>
#include <vector>

namespace nerfar {
namespace {

enum class Step { kFrame, kThrow, kLost, kEnd };

// Numbers its frames from 0 at 30 fps, as a freshly opened file or camera does.
class ScriptedSource : public FrameSource {
 public:
  explicit ScriptedSource(std::deque<Step> script) : script_(std::move(script)) {}
  std::string Describe() const override { return "scripted"; }
  FrameStatus Next(Frame& frame, int) override {
    const Step step = script_.empty() ? Step::kEnd : script_.front();
    if (!script_.empty()) script_.pop_front();
    switch (step) {
      case Step::kFrame:
        frame.image = Image8(4, 3, 3, 100);
        frame.index = next_++;
        frame.t_ns = frame.index * 33333333;
        return FrameStatus::kOk;
      case Step::kThrow:
        throw std::runtime_error("device vanished");
      case Step::kLost:
        return FrameStatus::kLost;
      case Step::kEnd:
        break;
    }
    return FrameStatus::kEndOfStream;
  }

 private:
  std::deque<Step> script_;
  std::int64_t next_ = 0;
};

// Opens the scripts one after the other; counts the openings.
struct Opener {
  std::vector<std::deque<Step>> scripts;
  int opened = 0;
  std::unique_ptr<FrameSource> operator()() {
    if (opened >= static_cast<int>(scripts.size())) throw std::runtime_error("no such device");
    return std::make_unique<ScriptedSource>(scripts[opened++]);
  }
};

ReconnectOptions Immediate(int lost_limit) {
  ReconnectOptions options;
  options.retry = std::chrono::milliseconds(0);  // every call may try again: no waiting in the test
  options.lost_limit = lost_limit;
  return options;
}

TEST(ReconnectingSource, ASourceThatThrowsIsOpenedAgainAndItsFramesCarryOn) {
  auto opener = std::make_shared<Opener>();
  opener->scripts = {{Step::kFrame, Step::kFrame, Step::kThrow}, {Step::kFrame, Step::kFrame}};
  std::unique_ptr<FrameSource> source = ReconnectOnLoss(
      nullptr, [opener] { return (*opener)(); }, Immediate(3));
  std::vector<FrameStatus> statuses;
  std::vector<std::int64_t> indices, stamps;
  for (int i = 0; i < 6; ++i) {
    Frame frame;
    const FrameStatus status = source->Next(frame, 10);
    statuses.push_back(status);
    if (status == FrameStatus::kOk) {
      indices.push_back(frame.index);
      stamps.push_back(frame.t_ns);
    }
  }
  // Two frames, the failure (reported as lost, with its reason), two frames
  // of the second opening, then its end.
  const std::vector<FrameStatus> expected = {FrameStatus::kOk, FrameStatus::kOk, FrameStatus::kLost,
                                             FrameStatus::kOk, FrameStatus::kOk, FrameStatus::kEndOfStream};
  EXPECT_EQ(statuses, expected);
  EXPECT_EQ(opener->opened, 2);
  EXPECT_EQ(indices, (std::vector<std::int64_t>{0, 1, 2, 3}));
  ASSERT_EQ(stamps.size(), 4u);
  for (size_t i = 1; i < stamps.size(); ++i) EXPECT_GT(stamps[i], stamps[i - 1]) << i;
}

TEST(ReconnectingSource, LostTooLongIsOpenedAgainAndAFailedOpeningIsRetried) {
  auto opener = std::make_shared<Opener>();
  // The first camera stays lost; reopening it fails once (scripts run out,
  // then a new script is added: the device is back).
  opener->scripts = {{Step::kFrame, Step::kLost, Step::kLost, Step::kLost, Step::kLost}};
  std::unique_ptr<FrameSource> source = ReconnectOnLoss(
      nullptr, [opener] { return (*opener)(); }, Immediate(2));
  Frame frame;
  ASSERT_EQ(source->Next(frame, 10), FrameStatus::kOk);
  EXPECT_EQ(source->Next(frame, 10), FrameStatus::kLost);
  EXPECT_EQ(source->Next(frame, 10), FrameStatus::kLost);  // the second in a row: closed
  EXPECT_EQ(source->Next(frame, 10), FrameStatus::kLost);  // opening fails: "no such device"
  EXPECT_NE(source->LastError().find("no such device"), std::string::npos) << source->LastError();
  opener->scripts.push_back({Step::kFrame});
  ASSERT_EQ(source->Next(frame, 10), FrameStatus::kOk);
  EXPECT_EQ(frame.index, 1);
  EXPECT_EQ(opener->opened, 2);
}

}  // namespace
}  // namespace nerfar
