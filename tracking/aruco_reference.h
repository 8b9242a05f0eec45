// OpenCV's aruco detector with its AprilTag dictionary (tag36h11 only), as a
// reference to compare our detector against on the same frames (the bench).
// Corners come out in our convention (continuous pixels, the board.json
// order TL, TR, BR, BL of the upright printed tag), ready for a Tracker's
// ProcessDetections.
#pragma once

#include <vector>

#include "calib/core/image.h"
#include "tracking/tag_detector.h"

namespace nerfar {

// Whether this build has OpenCV's aruco module.
bool ArucoAvailable();

// How aruco places corners: none (its quad fit), subpix (cornerSubPix on
// the corners), apriltag (its port of the AprilTag quad refinement).
enum class ArucoRefine { kNone, kSubpix, kAprilTag };

// Detects tag36h11 tags in a grey or RGB frame; empty where aruco is absent.
std::vector<TagDetection> DetectWithAruco(const Image8& image, ArucoRefine refine);

}  // namespace nerfar
