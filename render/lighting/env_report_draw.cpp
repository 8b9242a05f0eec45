// Drawing pieces of the environment report (env_report_draw.h).
#include "render/lighting/env_report_draw.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgproc.hpp>

#include "calib/core/error.h"
#include "calib/core/media.h"
#include "render/lighting/env_report.h"
#include "render/sg/sphere.h"

namespace nerfar {

std::array<std::uint8_t, 3> DivergingColour(double t) {
  // ColorBrewer RdBu, 5 classes, from blue (−1) to red (+1), interpolated in sRGB.
  static constexpr std::array<std::array<double, 3>, 5> kAnchors = {
      {{33, 102, 172}, {103, 169, 207}, {247, 247, 247}, {239, 138, 98}, {178, 24, 43}}};
  const double s = (std::clamp(std::isnan(t) ? 0.0 : t, -1.0, 1.0) + 1.0) * 2.0;  // 0..4
  const int k = std::min(3, static_cast<int>(s));
  const double f = s - k;
  std::array<std::uint8_t, 3> out;
  for (int c = 0; c < 3; ++c)
    out[c] = static_cast<std::uint8_t>(std::lround(kAnchors[k][c] + f * (kAnchors[k + 1][c] - kAnchors[k][c])));
  return out;
}

namespace env_report_internal {
namespace {

cv::Mat AsMat(Image8& image) {
  NERFAR_CHECK_EQ(image.channels, 3);
  return cv::Mat(image.height, image.width, CV_8UC3, image.pixels.data());
}

cv::Scalar ToScalar(const Colour& c) { return cv::Scalar(c[0], c[1], c[2]); }  // the Mat holds R,G,B as stored

const Colour kLobeColour = {120, 255, 90};
const Colour kRim = {20, 20, 20};

// Guides must read on a black sky and on a white sun: each pixel moves 80
// levels towards the middle grey from whichever side it is on.
void MarkGuidePixel(Image8& image, int x, int y) {
  if (x < 0 || y < 0 || x >= image.width || y >= image.height) return;
  std::uint8_t* p = image.Pixel(x, y);
  const int luma = (77 * p[0] + 150 * p[1] + 29 * p[2]) >> 8;
  for (int c = 0; c < 3; ++c) p[c] = static_cast<std::uint8_t>(std::clamp(p[c] + (luma < 128 ? 80 : -80), 0, 255));
}

Vec2 PanoramaPixel(const Vec3& direction, int width, int height) {
  double u = 0, v = 0;
  EquirectCoordinates(direction, &u, &v);
  return {u * width, v * height};
}

// The lobe's half-maximum circle as a polyline on the panorama, broken where it wraps around u = 0.
void DrawLobeCircle(cv::Mat& mat, const Sg& lobe, int thickness) {
  const double angle = LobeHalfMaxAngle(lobe.sharpness);
  if (!(angle < kPi)) return;
  const Vec3 a = Normalized(lobe.axis);
  const Vec3 t = Normalized(Cross(std::fabs(a.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, a));
  const Vec3 b = Cross(a, t);
  constexpr int kSegments = 96;
  Vec2 previous{};
  for (int k = 0; k <= kSegments; ++k) {
    const double phi = 2 * kPi * k / kSegments;
    const Vec3 d = a * std::cos(angle) + (t * std::cos(phi) + b * std::sin(phi)) * std::sin(angle);
    const Vec2 p = PanoramaPixel(d, mat.cols, mat.rows);
    if (k > 0 && std::fabs(p.x - previous.x) < 0.5 * mat.cols)
      cv::line(mat, cv::Point2d(previous.x, previous.y), cv::Point2d(p.x, p.y), ToScalar(kLobeColour), thickness,
               cv::LINE_AA);
    previous = p;
  }
}

}  // namespace

double LobeHalfMaxAngle(double sharpness) {
  const double c = 1.0 - std::log(2.0) / sharpness;
  return c <= -1.0 ? kPi : std::acos(c);
}

void DrawPanoramaGuides(Image8& panorama) {
  const int w = panorama.width, h = panorama.height;
  for (int elevation = -60; elevation <= 60; elevation += 30) {
    const int y = static_cast<int>(std::lround((90.0 - elevation) / 180.0 * h));
    for (int x = 0; x < w; ++x)
      if (elevation == 0 || (x / 3) % 2 == 0) MarkGuidePixel(panorama, x, y);
    char label[8];
    std::snprintf(label, sizeof label, "%+d", elevation);
    DrawText(panorama, elevation == 0 ? "0" : label, 3, y - 12, 0.8);
  }
  // Azimuth φ = π(1 − 2u): +x at u = 1/2, +y at 1/4, −y at 3/4, −x at the edges.
  const struct {
    double u;
    const char* name;
  } azimuths[] = {{0.25, "+y"}, {0.5, "+x"}, {0.75, "-y"}};
  for (const auto& a : azimuths) {
    const int x = static_cast<int>(std::lround(a.u * w));
    for (int y = 0; y < h; ++y)
      if ((y / 3) % 2 == 0) MarkGuidePixel(panorama, x, y);
    DrawText(panorama, a.name, x + 3, h / 2 + 3, 0.8);
  }
  DrawText(panorama, "-x", w - 18, h / 2 + 3, 0.8);
}

double LobeEnergy(const Sg& lobe) { return LuminanceOf(lobe.amplitude) * SgUnitIntegral(lobe.sharpness); }

std::vector<size_t> LobesByEnergy(const SgMixture& lobes) {
  std::vector<double> energy;
  for (const Sg& lobe : lobes) energy.push_back(LobeEnergy(lobe));
  std::vector<size_t> order(lobes.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return energy[a] > energy[b]; });
  return order;
}

void DrawLobes(Image8& panorama, const SgMixture& lobes, int labelled, bool labelled_only) {
  cv::Mat mat = AsMat(panorama);
  const std::vector<size_t> order = LobesByEnergy(lobes);
  for (size_t rank = 0; rank < order.size(); ++rank) {
    const Sg& lobe = lobes[order[rank]];
    const bool numbered = static_cast<int>(rank) < labelled;
    if (labelled_only && !numbered) break;
    DrawLobeCircle(mat, lobe, numbered ? 2 : 1);
    const Vec2 p = PanoramaPixel(Normalized(lobe.axis), mat.cols, mat.rows);
    const cv::Point c(static_cast<int>(p.x), static_cast<int>(p.y));
    cv::line(mat, c - cv::Point(4, 0), c + cv::Point(4, 0), ToScalar(kLobeColour), 1);
    cv::line(mat, c - cv::Point(0, 4), c + cv::Point(0, 4), ToScalar(kLobeColour), 1);
    if (numbered) DrawText(panorama, std::to_string(rank + 1), c.x + 5, c.y - 14, 1.0);
  }
}

void DrawDot(Image8& image, const Vec2& pixel, double radius, const Colour& colour) {
  cv::Mat mat = AsMat(image);
  // cv::circle takes integer centres: 4 fractional bits keep the sub-pixel position.
  constexpr int kShift = 4;
  const cv::Point centre(static_cast<int>(std::lround(pixel.x * (1 << kShift) - (1 << (kShift - 1)))),
                         static_cast<int>(std::lround(pixel.y * (1 << kShift) - (1 << (kShift - 1)))));
  const int r = static_cast<int>(std::lround(radius * (1 << kShift)));
  cv::circle(mat, centre, r + (1 << kShift), ToScalar(kRim), cv::FILLED, cv::LINE_AA, kShift);
  cv::circle(mat, centre, r, ToScalar(colour), cv::FILLED, cv::LINE_AA, kShift);
}

Image8 ResidualLegend(int width, double scale_log2, const std::string& low_words, const std::string& high_words) {
  constexpr int kBarHeight = 12, kHeight = 44;
  Image8 legend(width, kHeight, 3, 24);
  const int x0 = 8, x1 = width - 8;
  for (int x = x0; x < x1; ++x) {
    const Colour c = DivergingColour(2.0 * (x - x0 + 0.5) / (x1 - x0) - 1.0);
    for (int y = 2; y < 2 + kBarHeight; ++y)
      for (int ch = 0; ch < 3; ++ch) legend.at(x, y, ch) = c[ch];
  }
  for (double t : {-1.0, -0.5, 0.0, 0.5, 1.0}) {
    const int x = x0 + static_cast<int>(std::lround((t + 1.0) / 2.0 * (x1 - x0 - 1)));
    for (int y = 2 + kBarHeight; y < 2 + kBarHeight + 4; ++y)
      for (int ch = 0; ch < 3; ++ch) legend.at(x, y, ch) = 240;
    char label[16];
    std::snprintf(label, sizeof label, "x%.2g", std::exp2(t * scale_log2));
    DrawText(legend, label, std::clamp(x - 12, 0, width - 40), 2 + kBarHeight + 4, 0.9);
  }
  DrawText(legend, low_words, x0, kHeight - 12, 0.9);
  DrawText(legend, high_words, std::max(x0, x1 - 7 * static_cast<int>(high_words.size())), kHeight - 12, 0.9);
  return legend;
}

Image8 HemisphereDots(int size, const std::vector<Vec3>& normals, const std::vector<double>& values, double scale) {
  NERFAR_CHECK_EQ(normals.size(), values.size());
  Image8 plot(size, size, 3, 24);
  cv::Mat mat = AsMat(plot);
  const double c = 0.5 * size, radius = 0.5 * size - 22;
  const cv::Scalar grey(110, 110, 110);
  cv::circle(mat, cv::Point2d(c, c), static_cast<int>(radius), grey, 1, cv::LINE_AA);  // horizon
  for (double elevation_deg : {30.0, 60.0})
    cv::circle(mat, cv::Point2d(c, c), static_cast<int>(radius * std::cos(elevation_deg * kPi / 180)), grey, 1,
               cv::LINE_AA);
  cv::line(mat, cv::Point2d(c - radius, c), cv::Point2d(c + radius, c), grey, 1);
  cv::line(mat, cv::Point2d(c, c - radius), cv::Point2d(c, c + radius), grey, 1);
  DrawText(plot, "+x", static_cast<int>(c + radius) + 3, static_cast<int>(c) - 6, 0.9);
  DrawText(plot, "-x", 2, static_cast<int>(c) - 6, 0.9);
  DrawText(plot, "+y", static_cast<int>(c) + 4, 2, 0.9);
  DrawText(plot, "-y", static_cast<int>(c) + 4, size - 12, 0.9);
  for (size_t i = 0; i < normals.size(); ++i)
    DrawDot(plot, {c + radius * normals[i].x, c - radius * normals[i].y}, 6.0, DivergingColour(values[i] / scale));
  return plot;
}

Image8 Resized(const Image8& image, int width, int height, bool nearest) {
  Image8 copy = image;
  cv::Mat out;
  cv::resize(cv::Mat(copy.height, copy.width, CV_8UC(copy.channels), copy.pixels.data()), out, cv::Size(width, height),
             0, 0, nearest ? cv::INTER_NEAREST : cv::INTER_LINEAR);
  Image8 result(width, height, image.channels);
  std::copy(out.data, out.data + result.pixels.size(), result.pixels.begin());
  return result;
}

Image8 GreyBackdrop(const Image8& grey, double gain) {
  NERFAR_CHECK_EQ(grey.channels, 1);
  Image8 out(grey.width, grey.height, 3);
  for (size_t p = 0; p < grey.PixelCount(); ++p)
    for (int c = 0; c < 3; ++c) out.pixels[p * 3 + c] = static_cast<std::uint8_t>(std::lround(grey.pixels[p] * gain));
  return out;
}

void Paste(Image8& page, const Image8& tile, int x, int y) {
  NERFAR_CHECK_EQ(page.channels, tile.channels);
  for (int j = 0; j < tile.height; ++j)
    for (int i = 0; i < tile.width; ++i) {
      if (x + i < 0 || y + j < 0 || x + i >= page.width || y + j >= page.height) continue;
      std::copy(tile.Pixel(i, j), tile.Pixel(i, j) + tile.channels, page.Pixel(x + i, y + j));
    }
}

}  // namespace env_report_internal
}  // namespace nerfar
