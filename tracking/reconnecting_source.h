// A frame source that outlives its device. The source it wraps is closed and
// opened again through `reopen` when it throws from Next() (which the
// interface forbids, but a driver or a library may) or reports kLost
// `lost_limit` times in a row (a camera unplugged: libcamera's stays lost);
// at most once per `retry`, as long as it takes. Meanwhile Next() waits up to
// its timeout and reports kLost, with the reason in LastError(). Frame
// numbers and time stamps carry on from the last frame across a reopening (a
// reopened file or stream counts from 0 again). kEndOfStream passes through.
#pragma once

#include <chrono>
#include <functional>
#include <memory>

#include "calib/core/frame_source.h"

namespace nerfar {

struct ReconnectOptions {
  std::chrono::milliseconds retry{500};  // least time between two attempts to open the source again
  int lost_limit = 10;                   // kLost reports in a row before the source is opened again
};

using SourceOpener = std::function<std::unique_ptr<FrameSource>()>;

// `source` is the source opened already (may be null: opened at the first Next()).
std::unique_ptr<FrameSource> ReconnectOnLoss(std::unique_ptr<FrameSource> source, SourceOpener reopen,
                                             ReconnectOptions options = {});

}  // namespace nerfar
