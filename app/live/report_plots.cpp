#include "app/live/report_plots.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "calib/core/media.h"

namespace nerfar {

namespace {

// Plot area inside the box: room for the title and legend above, the y
// labels on the left and the x labels below.
struct Area {
  double x_lo = 0, x_hi = 1, top = 1;
  int left = 0, top_px = 0, width = 1, height = 1;
  double Px(double x) const { return left + (x - x_lo) / std::max(1e-9, x_hi - x_lo) * width; }
  double Py(double y) const { return top_px + height - std::clamp(y / top, 0.0, 1.0) * height; }
};

Area MakeArea(const Plot& plot, int x0, int y0, int width, int height) {
  Area a;
  if (!plot.x.empty()) {
    a.x_lo = plot.x.front();
    a.x_hi = std::max(plot.x.back(), a.x_lo + 1e-3);
  }
  a.top = PlotTop(plot);
  a.left = x0 + 52;
  a.top_px = y0 + 20;
  a.width = std::max(1, width - 52 - 8);
  a.height = std::max(1, height - 20 - 16);
  return a;
}

std::string Fmt(double v, const char* format = "%.3g") {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string Rgb(const std::array<std::uint8_t, 3>& c) {
  return "rgb(" + std::to_string(c[0]) + "," + std::to_string(c[1]) + "," + std::to_string(c[2]) + ")";
}

// Cumulative tops of the stacked series per x (bottom of series s = top of s − 1).
std::vector<std::vector<double>> StackTops(const Plot& plot) {
  std::vector<std::vector<double>> tops;
  std::vector<double> sum(plot.x.size(), 0.0);
  for (const PlotSeries& s : plot.stacked) {
    for (size_t i = 0; i < sum.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.y[i])) sum[i] += std::max(0.0, s.y[i]);
    tops.push_back(sum);
  }
  return tops;
}

void FillRect(Image8& page, int x0, int y0, int x1, int y1, const std::array<std::uint8_t, 3>& rgb) {
  for (int y = std::max(0, y0); y < std::min(page.height, y1); ++y)
    for (int x = std::max(0, x0); x < std::min(page.width, x1); ++x)
      for (int c = 0; c < 3; ++c) page.at(x, y, c) = rgb[c];
}

void DrawLine(Image8& page, double xa, double ya, double xb, double yb, const std::array<std::uint8_t, 3>& rgb) {
  const int steps = std::max(1, static_cast<int>(std::ceil(std::max(std::abs(xb - xa), std::abs(yb - ya)))));
  for (int k = 0; k <= steps; ++k) {
    const double t = static_cast<double>(k) / steps;
    const int x = static_cast<int>(std::lround(xa + (xb - xa) * t)),
              y = static_cast<int>(std::lround(ya + (yb - ya) * t));
    FillRect(page, x, y, x + 2, y + 2, rgb);
  }
}

// Legend entries "■ name" left to right after the title.
std::vector<const PlotSeries*> LegendOf(const Plot& plot) {
  std::vector<const PlotSeries*> all;
  for (const auto* list : {&plot.stacked, &plot.lines, &plot.markers})
    for (const PlotSeries& s : *list) all.push_back(&s);
  return all;
}

}  // namespace

double PlotTop(const Plot& plot) {
  if (plot.y_max > 0) return plot.y_max;
  std::vector<double> values;
  for (const std::vector<double>& t : StackTops(plot)) values.insert(values.end(), t.begin(), t.end());
  for (const auto* list : {&plot.lines, &plot.markers})
    for (const PlotSeries& s : *list)
      for (double v : s.y)
        if (std::isfinite(v)) values.push_back(v);
  if (values.empty()) return 1.0;
  // A cold first frame can take ten times the rest: the range stops at twice
  // the 95th percentile, and what lies above runs off the top.
  std::sort(values.begin(), values.end());
  const double p95 = values[static_cast<size_t>(0.95 * (values.size() - 1))];
  const double top = std::min(values.back(), 2 * p95);
  return top > 0 ? top * 1.1 : 1.0;
}

std::string PlotSvg(const Plot& plot, int width, int height) {
  const Area a = MakeArea(plot, 0, 0, width, height);
  std::string svg = "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + std::to_string(width) + "\" height=\"" +
                    std::to_string(height) + "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"#181818\"/>\n";
  svg += "<text x=\"4\" y=\"13\" fill=\"#eee\">" + HtmlEscape(plot.title) + "</text>\n";
  double legend_x = 10 + 7.0 * plot.title.size();
  for (const PlotSeries* s : LegendOf(plot)) {
    svg += "<rect x=\"" + Fmt(legend_x, "%.0f") + "\" y=\"4\" width=\"9\" height=\"9\" fill=\"" + Rgb(s->rgb) +
           "\"/><text x=\"" + Fmt(legend_x + 12, "%.0f") + "\" y=\"13\" fill=\"#ccc\">" + HtmlEscape(s->name) +
           "</text>\n";
    legend_x += 24 + 6.5 * s->name.size();
  }
  svg += "<rect x=\"" + std::to_string(a.left) + "\" y=\"" + std::to_string(a.top_px) + "\" width=\"" +
         std::to_string(a.width) + "\" height=\"" + std::to_string(a.height) + "\" fill=\"none\" stroke=\"#555\"/>\n";
  if (plot.y_axis)
    for (double f : {0.0, 0.5, 1.0})
      svg += "<text x=\"" + std::to_string(a.left - 4) + "\" y=\"" + Fmt(a.Py(f * a.top) + 4, "%.0f") +
             "\" fill=\"#aaa\" text-anchor=\"end\">" + Fmt(f * a.top) + "</text>\n";
  svg += "<text x=\"" + std::to_string(a.left) + "\" y=\"" + std::to_string(height - 3) + "\" fill=\"#aaa\">" +
         Fmt(a.x_lo, "%.1f") + " s</text><text x=\"" + std::to_string(a.left + a.width) + "\" y=\"" +
         std::to_string(height - 3) + "\" fill=\"#aaa\" text-anchor=\"end\">" + Fmt(a.x_hi, "%.1f") + " s</text>\n";
  // Stacked series as areas between their cumulative bottom and top.
  const std::vector<std::vector<double>> tops = StackTops(plot);
  for (size_t s = 0; s < plot.stacked.size(); ++s) {
    std::string points;
    for (size_t i = 0; i < plot.x.size(); ++i)
      points += Fmt(a.Px(plot.x[i]), "%.1f") + "," + Fmt(a.Py(tops[s][i]), "%.1f") + " ";
    for (size_t i = plot.x.size(); i-- > 0;)
      points += Fmt(a.Px(plot.x[i]), "%.1f") + "," + Fmt(a.Py(s > 0 ? tops[s - 1][i] : 0.0), "%.1f") + " ";
    svg += "<polygon class=\"series\" data-name=\"" + HtmlEscape(plot.stacked[s].name) + "\" fill=\"" +
           Rgb(plot.stacked[s].rgb) + "\" points=\"" + points + "\"/>\n";
  }
  for (const PlotSeries& s : plot.lines) {
    std::string points;
    const auto flush = [&] {
      if (!points.empty())
        svg += "<polyline class=\"series\" data-name=\"" + HtmlEscape(s.name) + "\" fill=\"none\" stroke=\"" +
               Rgb(s.rgb) + "\" stroke-width=\"1.5\" points=\"" + points + "\"/>\n";
      points.clear();
    };
    for (size_t i = 0; i < plot.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) {
        flush();
        continue;
      }
      points += Fmt(a.Px(plot.x[i]), "%.1f") + "," + Fmt(a.Py(s.y[i]), "%.1f") + " ";
    }
    flush();
  }
  for (const PlotSeries& s : plot.markers)
    for (size_t i = 0; i < plot.x.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.y[i]))
        svg += "<circle class=\"series\" data-name=\"" + HtmlEscape(s.name) + "\" cx=\"" +
               Fmt(a.Px(plot.x[i]), "%.1f") + "\" cy=\"" + Fmt(a.Py(s.y[i]), "%.1f") + "\" r=\"3\" fill=\"" +
               Rgb(s.rgb) + "\"><title>" + Fmt(plot.x[i], "%.2f") + " s: " + Fmt(s.y[i], "%.4g") +
               "</title></circle>\n";
  return svg + "</svg>";
}

void DrawPlot(const Plot& plot, Image8& page, int x0, int y0, int width, int height) {
  const Area a = MakeArea(plot, x0, y0, width, height);
  FillRect(page, a.left, a.top_px, a.left + a.width, a.top_px + a.height, {16, 16, 16});
  DrawText(page, plot.title, x0 + 4, y0 + 3);
  int legend_x = x0 + 12 + 7 * static_cast<int>(plot.title.size());
  for (const PlotSeries* s : LegendOf(plot)) {
    FillRect(page, legend_x, y0 + 5, legend_x + 9, y0 + 14, s->rgb);
    DrawText(page, s->name, legend_x + 12, y0 + 3);
    legend_x += 24 + 7 * static_cast<int>(s->name.size());
  }
  if (plot.y_axis)
    for (double f : {0.0, 0.5, 1.0}) DrawText(page, Fmt(f * a.top), x0 + 2, static_cast<int>(a.Py(f * a.top)) - 6);
  DrawText(page, Fmt(a.x_lo, "%.1f") + " s", a.left, a.top_px + a.height + 2);
  DrawText(page, Fmt(a.x_hi, "%.1f") + " s", a.left + a.width - 40, a.top_px + a.height + 2);
  // Stacked: each pixel column shows the frame at or after its time.
  const std::vector<std::vector<double>> tops = StackTops(plot);
  if (!plot.x.empty())
    for (int px = 0; px < a.width; ++px) {
      const double x = a.x_lo + (px + 0.5) / a.width * (a.x_hi - a.x_lo);
      const size_t i =
          std::min<size_t>(plot.x.size() - 1, std::lower_bound(plot.x.begin(), plot.x.end(), x) - plot.x.begin());
      for (size_t s = 0; s < plot.stacked.size(); ++s) {
        const int y_top = static_cast<int>(std::lround(a.Py(tops[s][i])));
        const int y_bottom = static_cast<int>(std::lround(a.Py(s > 0 ? tops[s - 1][i] : 0.0)));
        FillRect(page, a.left + px, y_top, a.left + px + 1, y_bottom, plot.stacked[s].rgb);
      }
    }
  for (const PlotSeries& s : plot.lines)
    for (size_t i = 1; i < plot.x.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.y[i - 1]) && std::isfinite(s.y[i]))
        DrawLine(page, a.Px(plot.x[i - 1]), a.Py(s.y[i - 1]), a.Px(plot.x[i]), a.Py(s.y[i]), s.rgb);
  for (const PlotSeries& s : plot.markers)
    for (size_t i = 0; i < plot.x.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.y[i])) {
        const int x = static_cast<int>(std::lround(a.Px(plot.x[i]))), y = static_cast<int>(std::lround(a.Py(s.y[i])));
        FillRect(page, x - 2, y - 2, x + 3, y + 3, s.rgb);
      }
}

std::string Base64(const std::vector<std::uint8_t>& bytes) {
  static const char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const std::uint32_t b0 = bytes[i], b1 = i + 1 < bytes.size() ? bytes[i + 1] : 0,
                        b2 = i + 2 < bytes.size() ? bytes[i + 2] : 0;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[v & 63] : '=';
  }
  return out;
}

std::string HtmlEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

}  // namespace nerfar
