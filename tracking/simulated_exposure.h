// A camera whose exposure can be set, simulated from a source of fixed
// exposure (the synthetic stream), so bracket capture can be tested end to
// end: each frame is read back through `response` to relative exposure,
// scaled by exposure / base_exposure and written through the response again.
// What a real sensor would record beyond the source's own clipping is lost:
// values at 255 stay the brightest, whatever the scale.
#pragma once

#include <memory>

#include "calib/core/frame_source.h"
#include "calib/hdr.h"

namespace nerfar {

// The source's frames count as taken at base_exposure_us. InputError for an
// invalid response or a non-positive base exposure.
std::unique_ptr<FrameSource> SimulateExposureControl(std::unique_ptr<FrameSource> source, CameraResponse response,
                                                     double base_exposure_us);

}  // namespace nerfar
