// AprilTag detection (libapriltag behind this header). Input: an 8-bit grey
// or RGB frame. Output: per tag its id and the 4 corners of the outer black
// square in continuous pixel coordinates (origin at the image's top-left
// corner, pixel (i, j) covers [i, i+1] x [j, j+1], as calib/camera.h), in the
// order top-left, top-right, bottom-right, bottom-left of the printed tag read
// upright: the order of board.json and of OpenCV's aruco detector, so corners
// pair one-to-one with a Board. "Upright" follows board.json: the tag as
// OpenCV's aruco draws it, which is libapriltag's reference bitmap turned by
// 180 degrees (TagBitmap returns the upright image).
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"

namespace nerfar {

struct TagDetectorOptions {
  // Tag family: tag36h11 (default; the scenes' boards), tag25h9, tag16h5,
  // tag36h10, tagCircle21h7, tagCircle49h12, tagStandard41h12,
  // tagStandard52h13, tagCustom48h12.
  std::string family = "tag36h11";
  // Upsampling factor applied before detection (1 or 2). 2 finds tags of 2-3
  // pixels per cell (the shared scenes' 400x300 views) at 4x the cost.
  int upsample = 1;
  // Quad search on an image decimated by this factor (1, 1.5, 2, 3, 4...);
  // larger is faster and loses small tags. Corners are still refined at full
  // resolution when refine_edges is on.
  double decimate = 2.0;
  // Gaussian blur sigma (pixels) before the quad search; 0.8 helps very noisy
  // frames, negative values sharpen.
  double blur_sigma = 0.0;
  // Snap quad edges to strong gradients at full resolution (cheap; keep on).
  bool refine_edges = true;
  // Sharpening of the decoded bit pattern (libapriltag's default 0.25).
  double decode_sharpening = 0.25;
  // Bits the decoder may correct (0-2). 2 finds damaged tags but raises false
  // positives on textured scenes; 3 and more need gigabytes and are refused.
  int max_hamming = 1;
  // Detections whose decision margin (mean bit contrast, 0-255) is below this
  // are dropped as unreliable; 0 keeps all.
  double min_decision_margin = 0.0;
  // Worker threads of the detector (>= 1).
  int threads = 1;
  // Re-fit each edge of the black square to sub-pixel precision (the edge
  // position from the area under ink-to-paper profiles, in linear intensity)
  // and intersect the lines. Exact on clean frontal renders, but it made
  // poses worse on the shared scenes and the synthetic stream (by 2-5x in
  // translation, docs/BENCHMARKS.md), so it is off by default.
  bool refine_corners = false;
  // How frame values relate to light, for the 50% crossing: "srgb" (cameras),
  // "display" (sRGB after Reinhard x/(1+x): frames from ToneMapToDisplay,
  // e.g. tone-mapped EXR), "linear".
  std::string response = "srgb";

  // Every problem with the values, each as "field: what (expected)".
  std::vector<std::string> Validate() const;
  // Named presets: "fast", "balanced" (default), "accurate".
  static TagDetectorOptions Preset(const std::string& name);
};

struct TagDetection {
  int id = 0;
  std::array<Vec2, 4> corners;  // TL, TR, BR, BL of the printed tag, continuous pixels
  int hamming = 0;              // bits corrected
  double decision_margin = 0;   // mean bit contrast (0-255); low means doubtful
};

// Why a frame produced no detections (besides "no tag in view").
// Where the time of the last Detect went (milliseconds, wall clock).
struct DetectTimings {
  double prepare_ms = 0;  // grey conversion, upsampling
  double search_ms = 0;   // the library: threshold, quads, decode, its edge snap
  double refine_ms = 0;   // our sub-pixel edge re-fit
};

// A pixel rectangle [x0, x1) x [y0, y1) of the frame.
struct SearchRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int Width() const { return x1 - x0; }
  int Height() const { return y1 - y0; }
};

enum class DetectStatus {
  kOk,             // detection ran (the list may be empty)
  kImageTooSmall,  // below the detector's minimum size: nothing was attempted
  kBadImage,       // wrong channel count or inconsistent buffer
  kResourceError,  // the library failed to allocate memory or start threads
};
const char* DetectStatusName(DetectStatus status);

class TagDetector {
 public:
  // InputError listing every problem if the options are invalid.
  explicit TagDetector(const TagDetectorOptions& options = {});
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  const TagDetectorOptions& options() const;
  // Detects tags in a grey or RGB frame; never throws on frame content.
  // Detections are sorted by id; a duplicated id keeps the one with the larger
  // decision margin (a board has each id once).
  DetectStatus Detect(const Image8& image, std::vector<TagDetection>& detections);
  // The same, searching only inside `regions` (clipped to the frame; regions
  // below the detector's minimum size are skipped). A tracker passes the
  // neighbourhoods of the tags it expects; corners are in frame coordinates
  // and refined on the whole frame. An empty list searches nothing.
  DetectStatus DetectInRegions(const Image8& image, const std::vector<SearchRect>& regions,
                               std::vector<TagDetection>& detections);
  const DetectTimings& last_timings() const;
  // Message for the last non-kOk status.
  const std::string& last_error() const;

 private:
  DetectStatus Run(const Image8& image, const std::vector<SearchRect>* regions, std::vector<TagDetection>& detections);

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The upright printed image of tag `id` (0 black, 255 white), including
// the white border the library draws around the black square, so it is
// (black square side + 2) cells wide; one pixel per cell. InputError for an
// unknown family or id.
Image8 TagBitmap(const std::string& family, int id);
// Cells across the outer black square of the family (8 for tag36h11).
int TagBlackSquareCells(const std::string& family);
// Names of every supported family.
std::vector<std::string> TagFamilies();

}  // namespace nerfar
