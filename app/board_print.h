// The sheets of a board layout (calib/board_layout.h) as a vector PDF at exact
// print scale and as PNG images at a stated resolution. Each sheet carries its
// tags (black cells as one filled path per tag, so no seams), its text (the
// board, the printing instruction, how to lay it onto its neighbours), a
// 100 mm ruler to measure, and the cut / align lines between sheets. Both
// outputs are drawn from one list of shapes per sheet, in page millimetres.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "calib/board_layout.h"
#include "calib/core/image.h"

namespace nerfar {

struct SheetText {
  double x_mm = 0, y_mm = 0;  // baseline start, page millimetres (y down)
  double size_mm = 3;         // cap-to-descender height of the font
  std::string text;           // ASCII
};

struct SheetLine {
  double x0_mm = 0, y0_mm = 0, x1_mm = 0, y1_mm = 0;
  double width_mm = 0.2;
  bool dashed = false;
};

// A rectangle of ink; the rectangles of one path are filled together.
using SheetPath = std::vector<RectMm>;

struct Sheet {
  double width_mm = 0, height_mm = 0;
  std::vector<SheetPath> paths;
  std::vector<SheetLine> lines;
  std::vector<SheetText> texts;
};

// The length of the ruler on the sheets: the largest multiple of 10 mm, up to
// 100, that fits the widest text area (its end labels stick out 2 mm).
double RulerLengthMm(const BoardLayout& layout);

// The shapes of every sheet. `bitmaps` maps each id to its upright tag image
// (tracking's TagBitmap: the black square and the family's white border, one
// pixel per cell); `command` is the nerfar command that made the board, for
// the rescaling instruction.
std::vector<Sheet> DrawBoardSheets(const BoardLayout& layout, const std::map<int, Image8>& bitmaps,
                                   const std::string& command);

// All sheets as one PDF file (atomic).
void WriteSheetsPdf(const std::string& path, const std::vector<Sheet>& sheets);

// One sheet rasterised at `dpi` (grey; each pixel the ink's area over it).
Image8 RasteriseSheet(const Sheet& sheet, double dpi);

// A grey 8-bit PNG that states its resolution (pHYs chunk) so that viewers and
// printers print it at scale (atomic).
void WritePngWithDpi(const std::string& path, const Image8& image, double dpi);

}  // namespace nerfar
