// Plots of the session report, described once and drawn two ways: as
// inline SVG for report.html and into the RGB page of report.png. A plot
// is series over one x axis (seconds of the session): bars stacked per x
// (frame time by stage, tracking state as a strip), polylines (latency,
// jitter; NaN leaves a gap) and markers (light refits). Values are in the
// plot's unit; y runs from 0 to y_max (0: the data's maximum with 10 % room,
// at most 2.2 × its 95th percentile: outliers run off the top).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

struct PlotSeries {
  std::string name;
  std::array<std::uint8_t, 3> rgb{200, 200, 200};
  std::vector<double> y;  // one value per x (NaN: none)
};

struct Plot {
  std::string title;  // with the unit, e.g. "frame time by stage (ms)"
  std::vector<double> x;
  std::vector<PlotSeries> stacked, lines, markers;
  double y_max = 0;
  bool y_axis = true;  // false for strips whose height means nothing (tracking state)
};

// The y range the plot is drawn over (y_max, or from the data as above).
double PlotTop(const Plot& plot);

// <svg> element of the plot, width x height px, with a legend of every series.
std::string PlotSvg(const Plot& plot, int width, int height);
// The plot drawn into `page` (RGB) over the box (x0, y0, width, height).
void DrawPlot(const Plot& plot, Image8& page, int x0, int y0, int width, int height);

// RFC 4648 base64 (data: URIs of the page's images).
std::string Base64(const std::vector<std::uint8_t>& bytes);
// "&", "<", ">", '"' escaped for HTML text and attributes.
std::string HtmlEscape(const std::string& text);

}  // namespace nerfar
