// Printable tag boards: where each tag goes on which sheet of paper, and the
// board.json (calib/board.h) the sheets make once laid on the table.
//
// The board is a rectangle (the "canvas") in millimetres, origin at its
// top-left corner, x to the right, y down the page as printed. Its world frame
// (board.json) is in metres with the origin at the canvas centre, x to the
// right, y up the page, z up out of the paper: the table top is z = 0.
//
// Two layouts: "table-border" puts the tags in a ring along the canvas edges
// (objects stand in the middle; each tag's printed up points away from the
// centre, as on the shared scenes' boards), "grid" fills the canvas with tags
// (a calibration sheet for `nerfar calibrate`). Every tag keeps a white margin
// of 2 cells around its black square. A canvas larger than one sheet's
// printable area is cut into tiles, one per sheet; a tag never straddles two
// tiles, tiles without tags are not printed, and each sheet says how to lay
// it onto its neighbours (cut its left / top margin, lay the edge on their
// line). The layout also reserves room on each sheet for its text and ruler.
#pragma once

#include <string>
#include <vector>

#include "calib/board.h"

namespace nerfar {

struct Paper {
  std::string name;  // "A4", "letter", "A3" or "WxH mm"
  double width_mm = 0, height_mm = 0;
};

// "A4", "A3", "letter" (any case) or "210x297" (millimetres); InputError otherwise.
Paper ParsePaper(const std::string& text);

struct BoardLayoutOptions {
  Paper paper{"A4", 210.0, 297.0};
  double page_margin_mm = 8;  // unprinted border of each sheet (printers cannot print to the edge)
  double tag_size_mm = 30;    // edge of the tag's outer black square
  int black_cells = 8;        // cells across the black square (8 for tag36h11)
  std::string family = "tag36h11";
  std::string layout = "table-border";  // or "grid"
  int first_id = 0;
  // table-border: the board's outline (0 x 0: one sheet's printable area).
  double table_width_mm = 0, table_height_mm = 0;

  double CellMm() const { return tag_size_mm / black_cells; }
  // The square a tag occupies with its white margin (2 cells each side).
  double FootprintMm() const { return tag_size_mm + 4 * CellMm(); }
  // Every problem, "field: what (expected)".
  std::vector<std::string> Validate() const;
};

struct RectMm {
  double x = 0, y = 0, w = 0, h = 0;  // page millimetres, y down
};

struct PlacedTag {
  int id = 0;
  double x_mm = 0, y_mm = 0;  // centre on its page
  // Counter-clockwise quarter turns of the upright tag as seen on the page
  // (0: its up is the page's up; 1: its up points to the page's left).
  int quarter_turns = 0;
};

struct BoardPage {
  int number = 0;           // 1-based, in print order
  int column = 0, row = 0;  // its tile in the canvas's tiling
  RectMm tile;              // the part of the canvas it holds (page coordinates)
  double canvas_x_mm = 0;   // canvas coordinates of the tile's top-left corner
  double canvas_y_mm = 0;
  RectMm text_area;  // where its text and ruler go
  std::vector<PlacedTag> tags;
  int left_page = 0, top_page = 0;      // printed neighbours it is laid onto (0: none): cut that margin
  int right_page = 0, bottom_page = 0;  // printed neighbours laid onto it: draw the line they align to
};

struct BoardLayout {
  BoardLayoutOptions options;
  Paper paper;  // as used (turned to landscape when that takes fewer sheets)
  double canvas_width_mm = 0, canvas_height_mm = 0;
  int columns = 1, rows = 1;  // the tiling
  std::vector<BoardPage> pages;
  Board board;  // the tags in the world frame (metres), ids as placed
};

// The layout; InputError listing every problem with the options (and when no
// tag fits).
BoardLayout MakeBoardLayout(const BoardLayoutOptions& options);

// The board as printed at another scale (a ruler of 100 mm that measures
// `printed_mm / 100` of it): every length scaled about the origin.
Board ScaleBoard(const Board& board, double factor);

}  // namespace nerfar
