#include "app/board_print.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

constexpr double kTextMm = 3.0;        // body text height
constexpr double kLineStepMm = 4.6;    // baseline to baseline
constexpr double kCharWidthEm = 0.56;  // Helvetica's mean advance for mixed text, to wrap lines
constexpr double kPtPerMm = 72.0 / 25.4;

std::string Number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g", v);
  return buffer;
}

// A rectangle of the upright tag (u right, v down from its centre) turned
// `quarter_turns` counter-clockwise on the page about the tag's centre.
RectMm TurnedRect(double u0, double v0, double u1, double v1, int quarter_turns, double cx, double cy) {
  for (int k = 0; k < (quarter_turns & 3); ++k) {
    // Counter-clockwise on a page whose y points down: (u, v) -> (v, -u).
    const double a0 = v0, b0 = -u0, a1 = v1, b1 = -u1;
    u0 = std::min(a0, a1), u1 = std::max(a0, a1), v0 = std::min(b0, b1), v1 = std::max(b0, b1);
  }
  return {cx + u0, cy + v0, u1 - u0, v1 - v0};
}

// The black cells of one tag as rectangles (runs along each row of its bitmap).
SheetPath TagPath(const PlacedTag& tag, const Image8& bitmap, double cell_mm) {
  SheetPath path;
  const double half = 0.5 * bitmap.width * cell_mm;
  for (int j = 0; j < bitmap.height; ++j)
    for (int i = 0; i < bitmap.width;) {
      if (bitmap.at(i, j) >= 128) {
        ++i;
        continue;
      }
      int end = i;
      while (end < bitmap.width && bitmap.at(end, j) < 128) ++end;
      path.push_back(TurnedRect(i * cell_mm - half, j * cell_mm - half, end * cell_mm - half, (j + 1) * cell_mm - half,
                                tag.quarter_turns, tag.x_mm, tag.y_mm));
      i = end;
    }
  return path;
}

// Words of `text` in lines of at most `width_mm` at font height `size_mm`.
std::vector<std::string> Wrap(const std::string& text, double width_mm, double size_mm) {
  const size_t max_chars = size_t(std::max(10.0, width_mm / (kCharWidthEm * size_mm)));
  std::vector<std::string> lines;
  std::istringstream words(text);
  std::string word, line;
  while (words >> word) {
    if (!line.empty() && line.size() + 1 + word.size() > max_chars) {
      lines.push_back(line);
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
  }
  if (!line.empty()) lines.push_back(line);
  return lines;
}

// A ruler of `length_mm` with its left end at (x, y): a base line, ticks every
// millimetre (longer every 5 and 10) and the centimetres numbered below.
void DrawRuler(Sheet& sheet, double x, double y, double length_mm) {
  SheetPath ink;
  ink.push_back({x - 0.075, y, length_mm + 0.15, 0.2});
  for (int k = 0; k <= int(length_mm); ++k) {
    const double tick = k % 10 == 0 ? 4.5 : (k % 5 == 0 ? 3.0 : 2.0);
    ink.push_back({x + k - 0.075, y - tick, 0.15, tick});
    if (k % 10 == 0)
      sheet.texts.push_back({x + k - 0.6 * (k >= 100 ? 3 : (k >= 10 ? 2 : 1)), y + 3.4, 2.4, std::to_string(k / 10)});
  }
  sheet.texts.push_back({x + length_mm + 3, y + 0.2, 2.4, "cm"});
  sheet.paths.push_back(ink);
}

std::string TitleLine(const BoardLayout& layout, const BoardPage& page) {
  const BoardLayoutOptions& o = layout.options;
  const int last_id = o.first_id + int(layout.board.tags.size()) - 1;
  return "nerfar board: " + o.family + " ids " + std::to_string(o.first_id) + "-" + std::to_string(last_id) +
         ", tags " + Number(o.tag_size_mm) + " mm (the black square), " + o.layout + ", " + layout.paper.name +
         ", sheet " + std::to_string(page.number) + " of " + std::to_string(layout.pages.size()) + ".";
}

// How to lay the sheet onto its neighbours (several sheets only).
std::string JoiningLine(const BoardPage& page) {
  std::string out;
  if (page.left_page > 0)
    out += "Cut off the left margin along the dashed line and lay the cut edge on the line at the right of sheet " +
           std::to_string(page.left_page) + ", the ticks in line. ";
  if (page.top_page > 0)
    out += "Cut off the top margin along the dashed line and lay the cut edge on the line at the bottom of sheet " +
           std::to_string(page.top_page) + ", the ticks in line. ";
  if (page.right_page > 0 || page.bottom_page > 0) out += "Tape the sheets together flat, printed side up.";
  return out;
}

// Registration ticks every kTickStepMm of the canvas along a joining edge, so
// that two sheets laid edge to edge also line up along it.
constexpr double kTickStepMm = 20, kTickMm = 4;

// Cut lines (dashed) where this sheet is laid onto a neighbour, lines to lay
// a neighbour's cut edge on (solid), and ticks inside the tile along both.
void DrawJoiningLines(Sheet& sheet, const BoardPage& page, double margin_mm) {
  const RectMm& t = page.tile;
  // Page position of the first canvas multiple of the tick step at or after page coordinate `from`.
  const auto first_tick = [&](double from, double canvas_origin) {
    const double canvas = from - margin_mm + canvas_origin;
    return std::ceil(canvas / kTickStepMm) * kTickStepMm - canvas_origin + margin_mm;
  };
  const auto vertical = [&](double x, bool dashed, double inward) {
    sheet.lines.push_back({x, dashed ? 0 : t.y, x, dashed ? sheet.height_mm : t.y + t.h, 0.2, dashed});
    for (double y = first_tick(t.y, page.canvas_y_mm); y <= t.y + t.h; y += kTickStepMm)
      sheet.lines.push_back({x, y, x + inward * kTickMm, y, 0.2, false});
  };
  const auto horizontal = [&](double y, bool dashed, double inward) {
    sheet.lines.push_back({dashed ? 0 : t.x, y, dashed ? sheet.width_mm : t.x + t.w, y, 0.2, dashed});
    for (double x = first_tick(t.x, page.canvas_x_mm); x <= t.x + t.w; x += kTickStepMm)
      sheet.lines.push_back({x, y, x, y + inward * kTickMm, 0.2, false});
  };
  if (page.left_page > 0) vertical(t.x, true, 1);
  if (page.top_page > 0) horizontal(t.y, true, 1);
  if (page.right_page > 0) vertical(t.x + t.w, false, -1);
  if (page.bottom_page > 0) horizontal(t.y + t.h, false, -1);
}

void DrawText(Sheet& sheet, const BoardLayout& layout, const BoardPage& page, double ruler_mm,
              const std::string& command) {
  const RectMm& area = page.text_area;
  const bool grid = layout.options.layout == "grid";
  std::vector<std::string> paragraphs = {
      TitleLine(layout, page),
      "Print at 100 % (actual size, not 'fit to page'). The ruler must measure " + Number(ruler_mm) +
          " mm. If it does not, measure it and run: " + command +
          " --printed-ruler MEASURED_MM (rewrites board.json "
          "at the printed scale).",
      grid ? "Calibration sheet: fix it flat and film it from many angles: nerfar calibrate --board board.json."
           : "Lay the sheet" + std::string(layout.pages.size() > 1 ? "s" : "") +
                 " flat on the table, printed side up; the objects go in the middle, the tags stay in view.",
      JoiningLine(page)};
  double y = area.y + kLineStepMm;
  for (const std::string& paragraph : paragraphs)
    for (const std::string& line : Wrap(paragraph, area.w, kTextMm)) {
      if (y > area.y + area.h - (ruler_mm > 0 ? 10 : 1)) return;
      sheet.texts.push_back({area.x, y, kTextMm, line});
      y += kLineStepMm;
    }
  if (ruler_mm > 0 && area.w >= ruler_mm + 4 && y + 5 <= area.y + area.h - 4)
    DrawRuler(sheet, area.x + 1, y + 5, ruler_mm);
}

std::string PdfEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '(' || c == ')' || c == '\\') out += '\\';
    out += (c >= 32 && c < 127) ? c : '?';
  }
  return out;
}

// The content stream of one sheet: millimetres, y down (one transform at the start).
std::string PdfContent(const Sheet& sheet) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(4);
  char transform[96];
  std::snprintf(transform, sizeof transform, "%.9f 0 0 %.9f 0 %.6f cm\n", kPtPerMm, -kPtPerMm,
                sheet.height_mm * kPtPerMm);
  s << transform << "0 g 0 G\n";
  for (const SheetPath& path : sheet.paths) {
    for (const RectMm& r : path) s << r.x << ' ' << r.y << ' ' << r.w << ' ' << r.h << " re\n";
    s << "f\n";
  }
  for (const SheetLine& l : sheet.lines)
    s << l.width_mm << " w " << (l.dashed ? "[2 1.5] 0 d " : "[] 0 d ") << l.x0_mm << ' ' << l.y0_mm << " m " << l.x1_mm
      << ' ' << l.y1_mm << " l S\n";
  for (const SheetText& t : sheet.texts)
    s << "BT /F1 1 Tf " << t.size_mm << " 0 0 " << -t.size_mm << ' ' << t.x_mm << ' ' << t.y_mm << " Tm ("
      << PdfEscape(t.text) << ") Tj ET\n";
  return s.str();
}

std::uint32_t Crc32(const unsigned char* data, size_t size) {
  static const std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t n = 0; n < 256; ++n) {
      std::uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xedb88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xffffffffu;
  for (size_t i = 0; i < size; ++i) c = table[(c ^ data[i]) & 0xff] ^ (c >> 8);
  return c ^ 0xffffffffu;
}

void PutBigEndian(std::string& out, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out += char((v >> shift) & 0xff);
}

}  // namespace

double RulerLengthMm(const BoardLayout& layout) {
  double widest = 0;
  for (const BoardPage& page : layout.pages) widest = std::max(widest, page.text_area.w);
  return std::min(100.0, std::floor((widest - 4) / 10) * 10);
}

std::vector<Sheet> DrawBoardSheets(const BoardLayout& layout, const std::map<int, Image8>& bitmaps,
                                   const std::string& command) {
  std::vector<Sheet> sheets;
  const double ruler_mm = RulerLengthMm(layout);
  for (const BoardPage& page : layout.pages) {
    Sheet sheet;
    sheet.width_mm = layout.paper.width_mm;
    sheet.height_mm = layout.paper.height_mm;
    for (const PlacedTag& tag : page.tags)
      sheet.paths.push_back(TagPath(tag, bitmaps.at(tag.id), layout.options.CellMm()));
    DrawJoiningLines(sheet, page, layout.options.page_margin_mm);
    DrawText(sheet, layout, page, ruler_mm, command);
    sheets.push_back(std::move(sheet));
  }
  return sheets;
}

void WriteSheetsPdf(const std::string& path, const std::vector<Sheet>& sheets) {
  // Objects: 1 catalog, 2 page tree, 3 font, then a page and its content per sheet.
  std::vector<std::string> objects = {"<< /Type /Catalog /Pages 2 0 R >>", "",
                                      "<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>"};
  std::string kids;
  for (const Sheet& sheet : sheets) {
    const int page_object = int(objects.size()) + 1;
    kids += std::to_string(page_object) + " 0 R ";
    std::ostringstream page;
    page << "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 " << sheet.width_mm * kPtPerMm << ' '
         << sheet.height_mm * kPtPerMm << "] /Resources << /Font << /F1 3 0 R >> >> /Contents " << page_object + 1
         << " 0 R >>";
    objects.push_back(page.str());
    const std::string content = PdfContent(sheet);
    objects.push_back("<< /Length " + std::to_string(content.size()) + " >>\nstream\n" + content + "endstream");
  }
  objects[1] = "<< /Type /Pages /Kids [" + kids + "] /Count " + std::to_string(sheets.size()) + " >>";
  std::string pdf = "%PDF-1.4\n";
  std::vector<size_t> offsets;
  for (size_t i = 0; i < objects.size(); ++i) {
    offsets.push_back(pdf.size());
    pdf += std::to_string(i + 1) + " 0 obj\n" + objects[i] + "\nendobj\n";
  }
  const size_t xref = pdf.size();
  pdf += "xref\n0 " + std::to_string(objects.size() + 1) + "\n0000000000 65535 f \n";
  for (size_t offset : offsets) {
    char entry[24];
    std::snprintf(entry, sizeof entry, "%010zu 00000 n \n", offset);
    pdf += entry;
  }
  pdf += "trailer\n<< /Size " + std::to_string(objects.size() + 1) + " /Root 1 0 R >>\nstartxref\n" +
         std::to_string(xref) + "\n%%EOF\n";
  WriteFileAtomic(path, pdf);
}

Image8 RasteriseSheet(const Sheet& sheet, double dpi) {
  const double px_per_mm = dpi / 25.4;
  const int w = int(std::lround(sheet.width_mm * px_per_mm)), h = int(std::lround(sheet.height_mm * px_per_mm));
  std::vector<float> ink(size_t(w) * h, 0.0f);
  // Each rectangle adds the area it covers of every pixel (they do not overlap within a path).
  const auto fill = [&](const RectMm& r) {
    const double x0 = r.x * px_per_mm, x1 = (r.x + r.w) * px_per_mm;
    const double y0 = r.y * px_per_mm, y1 = (r.y + r.h) * px_per_mm;
    for (int y = std::max(0, int(std::floor(y0))); y < std::min(h, int(std::ceil(y1))); ++y) {
      const double cover_y = std::min(y1, y + 1.0) - std::max(y0, double(y));
      for (int x = std::max(0, int(std::floor(x0))); x < std::min(w, int(std::ceil(x1))); ++x)
        ink[size_t(y) * w + x] += float(cover_y * (std::min(x1, x + 1.0) - std::max(x0, double(x))));
    }
  };
  for (const SheetPath& path : sheet.paths)
    for (const RectMm& r : path) fill(r);
  for (const SheetLine& l : sheet.lines) {
    // Lines are horizontal or vertical here; dashes are drawn solid in the image.
    fill({std::min(l.x0_mm, l.x1_mm) - l.width_mm / 2, std::min(l.y0_mm, l.y1_mm) - l.width_mm / 2,
          std::abs(l.x1_mm - l.x0_mm) + l.width_mm, std::abs(l.y1_mm - l.y0_mm) + l.width_mm});
  }
  cv::Mat grey(h, w, CV_8UC1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      grey.at<std::uint8_t>(y, x) = std::uint8_t(std::lround(255.0 * (1.0 - std::min(1.0f, ink[size_t(y) * w + x]))));
  for (const SheetText& t : sheet.texts) {
    // Hershey simplex: a scale of 1 is about 22 pixels from cap to descender.
    const double scale = t.size_mm * px_per_mm / 22.0;
    cv::putText(grey, t.text, cv::Point(int(t.x_mm * px_per_mm), int(t.y_mm * px_per_mm)), cv::FONT_HERSHEY_SIMPLEX,
                scale, cv::Scalar(0), std::max(1, int(std::lround(scale * 1.6))), cv::LINE_AA);
  }
  Image8 out(w, h, 1);
  for (int y = 0; y < h; ++y) std::copy_n(grey.ptr<std::uint8_t>(y), w, out.Pixel(0, y));
  return out;
}

void WritePngWithDpi(const std::string& path, const Image8& image, double dpi) {
  NERFAR_CHECK_EQ(image.channels, 1);
  cv::Mat view(image.height, image.width, CV_8UC1, const_cast<std::uint8_t*>(image.pixels.data()));
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", view, png)) throw std::runtime_error(path + ": cannot encode PNG");
  // pHYs right after the signature (8 bytes) and IHDR (25 bytes): pixels per metre, unit 1 (metre).
  const std::uint32_t per_metre = std::uint32_t(std::lround(dpi / 0.0254));
  std::string chunk = "pHYs";
  PutBigEndian(chunk, per_metre);
  PutBigEndian(chunk, per_metre);
  chunk += char(1);
  std::string bytes(png.begin(), png.begin() + 33);
  PutBigEndian(bytes, 9);
  bytes += chunk;
  PutBigEndian(bytes, Crc32(reinterpret_cast<const unsigned char*>(chunk.data()), chunk.size()));
  bytes.append(png.begin() + 33, png.end());
  WriteFileAtomic(path, bytes);
}

}  // namespace nerfar
