#include "calib/core/frame_source.h"

namespace nerfar {

const char* FrameStatusName(FrameStatus status) {
  switch (status) {
    case FrameStatus::kOk:
      return "ok";
    case FrameStatus::kEndOfStream:
      return "end of stream";
    case FrameStatus::kTimeout:
      return "timeout";
    case FrameStatus::kCorrupt:
      return "corrupt frame";
    case FrameStatus::kLost:
      return "device lost";
  }
  return "unknown";
}

}  // namespace nerfar
