#include "tracking/tag_detector.h"

#include <apriltag/apriltag.h>
#include <apriltag/common/zarray.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h10.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <opencv2/imgproc.hpp>

#include "calib/core/error.h"
#include "calib/core/image_io.h"

namespace nerfar {
namespace {

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tag36h10", tag36h10_create, tag36h10_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
};

const FamilyEntry* FindFamily(const std::string& name) {
  for (const FamilyEntry& f : kFamilies)
    if (name == f.name) return &f;
  return nullptr;
}

// Owns one family object of the C library (it is not freed by the detector).
struct FamilyHandle {
  const FamilyEntry* entry = nullptr;
  apriltag_family_t* family = nullptr;
  explicit FamilyHandle(const FamilyEntry* e) : entry(e), family(e->create()) {}
  ~FamilyHandle() {
    if (family != nullptr) entry->destroy(family);
  }
  FamilyHandle(const FamilyHandle&) = delete;
  FamilyHandle& operator=(const FamilyHandle&) = delete;
};

std::string FamilyList() {
  std::string list;
  for (const FamilyEntry& f : kFamilies) list += std::string(list.empty() ? "" : ", ") + f.name;
  return list;
}

// libapriltag reports corners counter-clockwise; board.json (and OpenCV's
// aruco dictionary of the same family) define a tag's "upright printed image"
// as libapriltag's reference bitmap turned by 180 degrees (checked against
// OpenCV's drawn markers and the shared scenes' true poses). Our corner k
// (TL, TR, BR, BL of that printed image) is the library's kLibraryCorner[k].
constexpr int kLibraryCorner[4] = {1, 0, 3, 2};
// The library's pixel coordinates put pixel centres at integers; ours at +0.5.
constexpr double kLibraryPixelOffset = 0.5;

// Smallest side the library handles sensibly; below it the quad search works
// on a handful of pixels (and older releases read past the buffer).
constexpr int kMinSide = 16;

}  // namespace

std::vector<std::string> TagDetectorOptions::Validate() const {
  std::vector<std::string> problems;
  if (FindFamily(family) == nullptr)
    problems.push_back("family: '" + family + "' is unknown (expected one of " + FamilyList() + ")");
  if (upsample != 1 && upsample != 2)
    problems.push_back("upsample: " + std::to_string(upsample) + " (expected 1 or 2)");
  if (!(decimate >= 1.0 && decimate <= 8.0))
    problems.push_back("decimate: " + std::to_string(decimate) + " (expected 1 to 8)");
  if (!(std::abs(blur_sigma) <= 10.0))
    problems.push_back("blur_sigma: " + std::to_string(blur_sigma) + " (expected -10 to 10 pixels)");
  if (!(decode_sharpening >= 0.0 && decode_sharpening <= 10.0))
    problems.push_back("decode_sharpening: " + std::to_string(decode_sharpening) + " (expected 0 to 10)");
  if (max_hamming < 0 || max_hamming > 2)
    problems.push_back("max_hamming: " + std::to_string(max_hamming) + " (expected 0 to 2)");
  if (!(min_decision_margin >= 0.0 && min_decision_margin <= 255.0))
    problems.push_back("min_decision_margin: " + std::to_string(min_decision_margin) + " (expected 0 to 255)");
  if (response != "srgb" && response != "display" && response != "linear")
    problems.push_back("response: '" + response + "' is unknown (expected srgb, display or linear)");
  if (threads < 1 || threads > 64) problems.push_back("threads: " + std::to_string(threads) + " (expected 1 to 64)");
  return problems;
}

TagDetectorOptions TagDetectorOptions::Preset(const std::string& name) {
  TagDetectorOptions options;
  if (name == "fast") {
    options.decimate = 3.0;
  } else if (name == "balanced") {
    options.decimate = 2.0;
  } else if (name == "accurate") {
    options.decimate = 1.0;
  } else {
    ThrowInputError("detector preset", "'" + name + "' is unknown (expected fast, balanced or accurate)");
  }
  return options;
}

const char* DetectStatusName(DetectStatus status) {
  switch (status) {
    case DetectStatus::kOk:
      return "ok";
    case DetectStatus::kImageTooSmall:
      return "image too small";
    case DetectStatus::kBadImage:
      return "bad image";
    case DetectStatus::kResourceError:
      return "detector resource error";
  }
  return "unknown";
}

// Sub-pixel edge refinement (see TagDetectorOptions::refine_corners).
class EdgeRefiner {
 public:
  // Half-width of a profile's window (pixels) and profiles per edge: beyond
  // them a large tag costs more without a better line.
  static constexpr double kWindowPx = 6.0;
  static constexpr int kMaxProfiles = 48;

  EdgeRefiner(const cv::Mat& gray, const float* lut, int black_cells)
      : gray_(gray), lut_(lut), black_cells_(black_cells) {}

  // Refines the corners in place; leaves them unchanged where the tag is too
  // small, too faint or the fit disagrees with the detection.
  void Refine(std::array<Vec2, 4>& corners) const {
    std::array<Vec2, 4> point_on_line, direction;
    Vec2 centre{0, 0};
    for (const Vec2& c : corners) centre = {centre.x + c.x / 4, centre.y + c.y / 4};
    double cell_min = 1e30;
    for (int e = 0; e < 4; ++e) {
      const Vec2 a = corners[e], b = corners[(e + 1) % 4];
      const double length = std::hypot(b.x - a.x, b.y - a.y);
      const double cell = length / black_cells_;
      cell_min = std::min(cell_min, cell);
      if (cell < 1.2) return;  // a cell below ~1 pixel: nothing to refine against
      const Vec2 u{(b.x - a.x) / length, (b.y - a.y) / length};
      Vec2 n{-u.y, u.x};
      const Vec2 mid{(a.x + b.x) / 2, (a.y + b.y) / 2};
      if ((mid.x - centre.x) * n.x + (mid.y - centre.y) * n.y < 0) n = {-n.x, -n.y};  // outward
      // Ink and paper levels: medians at the centres of the black border
      // cell and of the white margin cell next to this edge.
      std::vector<float> dark, bright;
      for (double t = 0.5 / black_cells_; t < 1.0; t += 1.0 / black_cells_) {
        const Vec2 p{a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t};
        float v;
        if (Sample(p.x - n.x * 0.5 * cell, p.y - n.y * 0.5 * cell, v)) dark.push_back(v);
        if (Sample(p.x + n.x * 0.5 * cell, p.y + n.y * 0.5 * cell, v)) bright.push_back(v);
      }
      if (dark.size() < 3 || bright.size() < 3) return;
      const double d = Median(dark), w = Median(bright);
      if (!(w - d > 0.1 * w)) return;  // no usable contrast
      // Crossings along profiles across the edge, away from the corners.
      std::vector<Vec2> points;
      // The window spans the blurred step (a few pixels) and the detection's
      // error, within the border cell and the white margin.
      const double inner = std::min(0.7 * cell, kWindowPx), outer = std::min(0.9 * cell, kWindowPx), step = 0.25;
      const int profiles = std::clamp(static_cast<int>(length / 0.5), 6, kMaxProfiles);
      for (int k = 0; k < profiles; ++k) {
        const double t = 0.12 + 0.76 * (k + 0.5) / profiles;
        const Vec2 p{a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t};
        // Edge position from the area under the normalised profile: for a
        // step edge blurred by any symmetric kernel, the integral of
        // (I - dark) / (paper - dark) from the inner end to the outer end
        // equals (outer end - edge). Unbiased for box-filtered pixels, where
        // a 50% crossing of interpolated samples is not.
        double area = 0, previous = 0;
        bool inside = true;
        int count = 0;
        for (double s = -inner; s <= outer + 1e-9; s += step, ++count) {
          float v;
          if (!Sample(p.x + n.x * s, p.y + n.y * s, v)) {
            inside = false;
            break;
          }
          const double f = std::clamp((v - d) / (w - d), -0.5, 1.5);
          if (count > 0) area += 0.5 * (previous + f) * step;
          previous = f;
        }
        const double span = step * (count - 1);
        double best = inside ? -inner + span - area : 1e30;
        if (std::abs(best) > 0.5 * cell) best = 1e30;  // another edge in the window
        if (best < 1e29) points.push_back({p.x + n.x * best, p.y + n.y * best});
      }
      if (points.size() < 4) return;
      // Total least squares line through the crossings.
      double mx = 0, my = 0;
      for (const Vec2& q : points) {
        mx += q.x;
        my += q.y;
      }
      mx /= points.size();
      my /= points.size();
      double sxx = 0, sxy = 0, syy = 0;
      for (const Vec2& q : points) {
        sxx += (q.x - mx) * (q.x - mx);
        sxy += (q.x - mx) * (q.y - my);
        syy += (q.y - my) * (q.y - my);
      }
      const double angle = 0.5 * std::atan2(2 * sxy, sxx - syy);
      point_on_line[e] = {mx, my};
      direction[e] = {std::cos(angle), std::sin(angle)};
    }
    std::array<Vec2, 4> refined;
    for (int c = 0; c < 4; ++c) {
      // Corner c joins edge c-1 (ending at it) and edge c (starting at it).
      const int e0 = (c + 3) % 4, e1 = c;
      const Vec2 p0 = point_on_line[e0], d0 = direction[e0], p1 = point_on_line[e1], d1 = direction[e1];
      const double det = d0.x * (-d1.y) - d0.y * (-d1.x);
      if (std::abs(det) < 1e-6) return;
      const double rx = p1.x - p0.x, ry = p1.y - p0.y;
      const double t = (rx * (-d1.y) - ry * (-d1.x)) / det;
      refined[c] = {p0.x + d0.x * t, p0.y + d0.y * t};
      // A fit that moves a corner by more than half a cell went astray.
      if (std::hypot(refined[c].x - corners[c].x, refined[c].y - corners[c].y) > 0.5 * cell_min) return;
    }
    corners = refined;
  }

 private:
  static double Median(std::vector<float>& v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  }

  // Bilinear sample of the linearised image at a continuous coordinate.
  bool Sample(double x, double y, float& value) const {
    const double fx = x - 0.5, fy = y - 0.5;  // pixel centres at +0.5
    const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
    if (x0 < 0 || y0 < 0 || x0 + 1 >= gray_.cols || y0 + 1 >= gray_.rows) return false;
    const double ax = fx - x0, ay = fy - y0;
    const std::uint8_t* r0 = gray_.ptr<std::uint8_t>(y0);
    const std::uint8_t* r1 = gray_.ptr<std::uint8_t>(y0 + 1);
    value = static_cast<float>((1 - ay) * ((1 - ax) * lut_[r0[x0]] + ax * lut_[r0[x0 + 1]]) +
                               ay * ((1 - ax) * lut_[r1[x0]] + ax * lut_[r1[x0 + 1]]));
    return true;
  }

  const cv::Mat& gray_;
  const float* lut_;
  int black_cells_;
};

struct TagDetector::Impl {
  TagDetectorOptions options;
  std::unique_ptr<FamilyHandle> family;
  apriltag_detector_t* detector = nullptr;
  std::string last_error;
  cv::Mat gray, upsampled;
  DetectTimings timings;
  float lut[256];  // 8-bit value -> relative linear intensity
  int black_cells = 8;
  bool can_refine = true;  // families with a reversed border have no ink-inside edge

  ~Impl() {
    if (detector != nullptr) apriltag_detector_destroy(detector);
  }
};

TagDetector::TagDetector(const TagDetectorOptions& options) : impl_(std::make_unique<Impl>()) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("tag detector options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
  impl_->options = options;
  impl_->family = std::make_unique<FamilyHandle>(FindFamily(options.family));
  if (impl_->family->family == nullptr)
    throw std::runtime_error("tag detector: cannot create family " + options.family);
  impl_->detector = apriltag_detector_create();
  if (impl_->detector == nullptr) throw std::runtime_error("tag detector: cannot create the detector (out of memory)");
  errno = 0;
  apriltag_detector_add_family_bits(impl_->detector, impl_->family->family, options.max_hamming);
  // The library prints and leaves the family out when its decode table cannot
  // be allocated; errno is the only trace.
  if (errno == ENOMEM || zarray_size(impl_->detector->tag_families) != 1)
    throw std::runtime_error("tag detector: cannot build the decode table of " + options.family + " (out of memory)");
  apriltag_detector_t* td = impl_->detector;
  td->quad_decimate = static_cast<float>(options.decimate);
  td->quad_sigma = static_cast<float>(options.blur_sigma);
  td->refine_edges = options.refine_edges;
  td->decode_sharpening = options.decode_sharpening;
  td->nthreads = options.threads;
  td->debug = false;
  impl_->black_cells = impl_->family->family->width_at_border;
  impl_->can_refine = !impl_->family->family->reversed_border;
  for (int i = 0; i < 256; ++i) {
    // Clip below full scale: a saturated pixel's true value is unknown.
    const float v = std::min(static_cast<float>(i), 254.5f) / 255.0f;
    if (options.response == "linear") {
      impl_->lut[i] = v;
    } else {
      const float srgb_inverse = SrgbToLinear(v);
      // Reinhard tm = x/(1+x) inverts to x = tm/(1-tm), up to the exposure scale.
      impl_->lut[i] = options.response == "display" ? srgb_inverse / (1.0f - srgb_inverse) : srgb_inverse;
    }
  }
}

TagDetector::~TagDetector() = default;

const TagDetectorOptions& TagDetector::options() const { return impl_->options; }
const std::string& TagDetector::last_error() const { return impl_->last_error; }

DetectStatus TagDetector::Detect(const Image8& image, std::vector<TagDetection>& detections) {
  return Run(image, nullptr, detections);
}

DetectStatus TagDetector::DetectInRegions(const Image8& image, const std::vector<SearchRect>& regions,
                                          std::vector<TagDetection>& detections) {
  return Run(image, &regions, detections);
}

const DetectTimings& TagDetector::last_timings() const { return impl_->timings; }

DetectStatus TagDetector::Run(const Image8& image, const std::vector<SearchRect>* regions,
                              std::vector<TagDetection>& detections) {
  using Clock = std::chrono::steady_clock;
  const auto ms_since = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };
  detections.clear();
  impl_->last_error.clear();
  impl_->timings = {};
  if ((image.channels != 1 && image.channels != 3 && image.channels != 4) || image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != image.PixelCount() * static_cast<size_t>(image.channels)) {
    impl_->last_error = "frame of " + std::to_string(image.width) + "x" + std::to_string(image.height) + "x" +
                        std::to_string(image.channels) + " with " + std::to_string(image.pixels.size()) +
                        " bytes (expected 1, 3 or 4 channels, width*height*channels bytes)";
    return DetectStatus::kBadImage;
  }
  const TagDetectorOptions& o = impl_->options;
  const int min_side = static_cast<int>(std::ceil(kMinSide * o.decimate / o.upsample));
  if (image.width < min_side || image.height < min_side) {
    impl_->last_error = "frame of " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                        " is below the detector's minimum of " + std::to_string(min_side) + " pixels a side";
    return DetectStatus::kImageTooSmall;
  }
  auto t = Clock::now();
  cv::Mat view(image.height, image.width, CV_8UC(image.channels), const_cast<std::uint8_t*>(image.pixels.data()));
  if (image.channels == 1) {
    impl_->gray = view;
  } else {
    cv::cvtColor(view, impl_->gray, image.channels == 3 ? cv::COLOR_RGB2GRAY : cv::COLOR_RGBA2GRAY);
  }
  // The areas searched, in frame pixels.
  std::vector<SearchRect> areas;
  if (regions == nullptr) {
    areas.push_back({0, 0, image.width, image.height});
  } else {
    for (SearchRect r : *regions) {
      r.x0 = std::max(r.x0, 0);
      r.y0 = std::max(r.y0, 0);
      r.x1 = std::min(r.x1, image.width);
      r.y1 = std::min(r.y1, image.height);
      if (r.Width() >= min_side && r.Height() >= min_side) areas.push_back(r);
    }
  }
  impl_->timings.prepare_ms = ms_since(t);

  std::map<int, TagDetection> by_id;
  const double scale = 1.0 / o.upsample;
  for (const SearchRect& area : areas) {
    t = Clock::now();
    cv::Mat crop = impl_->gray(cv::Rect(area.x0, area.y0, area.Width(), area.Height()));
    if (o.upsample == 2) {
      cv::resize(crop, impl_->upsampled, cv::Size(), 2.0, 2.0, cv::INTER_LINEAR);
      crop = impl_->upsampled;
    }
    impl_->timings.prepare_ms += ms_since(t);
    t = Clock::now();
    // The library reads rows through `stride`: a crop of the frame needs no copy.
    image_u8_t im{crop.cols, crop.rows, static_cast<int32_t>(crop.step[0]), crop.data};
    errno = 0;
    zarray_t* found = apriltag_detector_detect(impl_->detector, &im);
    const int error = errno;
    impl_->timings.search_ms += ms_since(t);
    if (found == nullptr) {
      impl_->last_error = std::string("detector returned nothing (") + std::strerror(error ? error : ENOMEM) + ")";
      return DetectStatus::kResourceError;
    }
    const int count = zarray_size(found);
    // Thread-pool creation failures return an empty list with errno set.
    if (count == 0 && (error == EAGAIN || error == ENOMEM)) {
      apriltag_detections_destroy(found);
      impl_->last_error = std::string("detector could not start its threads (") + std::strerror(error) + ")";
      return DetectStatus::kResourceError;
    }
    for (int i = 0; i < count; ++i) {
      apriltag_detection_t* det = nullptr;
      zarray_get(found, i, &det);
      if (det == nullptr) continue;
      if (det->decision_margin < o.min_decision_margin) continue;
      TagDetection d;
      d.id = det->id;
      d.hamming = det->hamming;
      d.decision_margin = det->decision_margin;
      bool finite = true;
      for (int k = 0; k < 4; ++k) {
        const double* p = det->p[kLibraryCorner[k]];
        // Library pixel centres at integers (in the upsampled crop) ->
        // continuous coordinates of the frame.
        d.corners[k] = {(p[0] + kLibraryPixelOffset) * scale + area.x0, (p[1] + kLibraryPixelOffset) * scale + area.y0};
        finite = finite && std::isfinite(p[0]) && std::isfinite(p[1]);
      }
      if (!finite) continue;
      auto it = by_id.find(d.id);
      if (it == by_id.end() || it->second.decision_margin < d.decision_margin) by_id[d.id] = d;
    }
    apriltag_detections_destroy(found);
  }
  t = Clock::now();
  const EdgeRefiner refiner(impl_->gray, impl_->lut, impl_->black_cells);
  for (auto& [id, d] : by_id) {
    if (o.refine_corners && impl_->can_refine) refiner.Refine(d.corners);
    detections.push_back(d);
  }
  impl_->timings.refine_ms = ms_since(t);
  return DetectStatus::kOk;
}

Image8 TagBitmap(const std::string& family, int id) {
  const FamilyEntry* entry = FindFamily(family);
  if (entry == nullptr)
    ThrowInputError("tag family", "'" + family + "' is unknown (expected one of " + FamilyList() + ")");
  FamilyHandle handle(entry);
  if (id < 0 || static_cast<uint32_t>(id) >= handle.family->ncodes)
    ThrowInputError("tag id", std::to_string(id) + " is not in " + family + " (expected 0 to " +
                                  std::to_string(handle.family->ncodes - 1) + ")");
  image_u8_t* im = apriltag_to_image(handle.family, id);
  if (im == nullptr) throw std::runtime_error("tag bitmap: out of memory");
  // Turned by 180 degrees: the printed-upright image of board.json.
  Image8 out(im->width, im->height, 1);
  for (int y = 0; y < im->height; ++y)
    for (int x = 0; x < im->width; ++x) out.at(im->width - 1 - x, im->height - 1 - y) = im->buf[y * im->stride + x];
  // The library's image_u8_destroy is not exported by the Debian build; the
  // image is one malloc for the struct and one for the pixels.
  std::free(im->buf);
  std::free(im);
  return out;
}

int TagBlackSquareCells(const std::string& family) {
  const FamilyEntry* entry = FindFamily(family);
  if (entry == nullptr)
    ThrowInputError("tag family", "'" + family + "' is unknown (expected one of " + FamilyList() + ")");
  FamilyHandle handle(entry);
  return handle.family->width_at_border;
}

std::vector<std::string> TagFamilies() {
  std::vector<std::string> names;
  for (const FamilyEntry& f : kFamilies) names.push_back(f.name);
  return names;
}

}  // namespace nerfar
