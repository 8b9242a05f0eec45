#include "calib/board_layout.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>

#include "calib/core/error.h"

namespace nerfar {
namespace {

// Height kept under a grid for the sheet's text and ruler (title, the
// instruction, a 100 mm ruler with its numbers: about 6 lines of 3.5 mm).
constexpr double kTextStripMm = 34;
// Placements are computed in millimetres from sums of a few lengths: a
// footprint that fits within rounding fits.
constexpr double kFitSlackMm = 1e-6;

std::string Lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string Mm(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g", v);
  return buffer;
}

// Where sheets meet along one axis of the canvas: tile k covers
// [k · tile - offset, (k + 1) · tile - offset).
struct Tiling {
  double tile = 0, offset = 0;
  int count = 1;

  int Of(double x) const { return int(std::floor((x + offset) / tile)); }
  double Start(int k) const { return k * tile - offset; }
};

// The tiling of [0, length] by tiles of `tile` whose end tiles are at least
// `band` long (a band of tags along each canvas edge then lies within one
// tile): the tiles start `offset` before the canvas where the last one would
// otherwise be too short. InputError when no offset does it.
Tiling TileAxis(double length, double tile, double band) {
  Tiling t{tile, 0, int(std::ceil(length / tile - kFitSlackMm))};
  if (t.count == 1) return t;
  const double last = length - (t.count - 1) * tile;
  if (last < band - kFitSlackMm) t.offset = band - last;
  if (tile - t.offset < band - kFitSlackMm)
    ThrowInputError("board", "the sheets' printable width " + Mm(tile) + " mm cannot hold a band of tags " + Mm(band) +
                                 " mm wide at both ends of a " + Mm(length) +
                                 " mm table side (expected a smaller --tag-size or a larger --paper)");
  t.count = int(std::ceil((length + t.offset) / tile - kFitSlackMm));
  return t;
}

// Centres of as many footprints of size f as fit in [a, b] without crossing a
// sheet's edge, spread evenly within each piece.
std::vector<double> PlaceAlong(double a, double b, const Tiling& tiling, double f) {
  std::vector<double> centres;
  double p = a;
  while (p < b - kFitSlackMm) {
    const double q = std::min(b, tiling.Start(tiling.Of(p + kFitSlackMm) + 1));
    const int n = int(std::floor((q - p) / f + kFitSlackMm));
    for (int i = 0; i < n; ++i) centres.push_back(p + (q - p) / n * (i + 0.5));
    p = q;
  }
  return centres;
}

struct CanvasTag {
  double x = 0, y = 0;  // canvas millimetres
  int quarter_turns = 0;
};

// The ring along the canvas edges, clockwise from the top-left: top row left
// to right, right column down, bottom row right to left, left column up.
std::vector<CanvasTag> RingTags(double w, double h, double f, const Tiling& columns, const Tiling& rows) {
  std::vector<CanvasTag> tags;
  for (double x : PlaceAlong(0, w, columns, f)) tags.push_back({x, f / 2, 0});
  for (double y : PlaceAlong(f, h - f, rows, f)) tags.push_back({w - f / 2, y, 3});
  std::vector<double> bottom = PlaceAlong(0, w, columns, f);
  for (auto it = bottom.rbegin(); it != bottom.rend(); ++it) tags.push_back({*it, h - f / 2, 2});
  std::vector<double> left = PlaceAlong(f, h - f, rows, f);
  for (auto it = left.rbegin(); it != left.rend(); ++it) tags.push_back({f / 2, *it, 1});
  return tags;
}

std::vector<CanvasTag> GridTags(double w, double h, double f, const Tiling& columns, const Tiling& rows) {
  std::vector<CanvasTag> tags;
  for (double y : PlaceAlong(0, h, rows, f))
    for (double x : PlaceAlong(0, w, columns, f)) tags.push_back({x, y, 0});
  return tags;
}

// The printed up direction of a tag turned `quarter_turns` counter-clockwise
// on the page, in the world frame (y up the page).
Vec3 UpDirection(int quarter_turns) {
  switch (quarter_turns & 3) {
    case 0:
      return {0, 1, 0};
    case 1:
      return {-1, 0, 0};
    case 2:
      return {0, -1, 0};
    default:
      return {1, 0, 0};
  }
}

BoardTag WorldTag(int id, const CanvasTag& t, double canvas_w, double canvas_h, double size_mm) {
  BoardTag tag;
  tag.id = id;
  tag.center = {(t.x - canvas_w / 2) / 1000, (canvas_h / 2 - t.y) / 1000, 0};
  tag.up_direction = UpDirection(t.quarter_turns);
  const Vec3 right = Cross(tag.up_direction, Vec3{0, 0, 1});
  const Vec3 up = tag.up_direction * (size_mm / 2000), across = right * (size_mm / 2000);
  tag.corners = {tag.center + up - across, tag.center + up + across, tag.center - up + across,
                 tag.center - up - across};
  return tag;
}

RectMm Intersect(const RectMm& a, const RectMm& b) {
  const double x0 = std::max(a.x, b.x), y0 = std::max(a.y, b.y);
  const double x1 = std::min(a.x + a.w, b.x + b.w), y1 = std::min(a.y + a.h, b.y + b.h);
  return x1 > x0 && y1 > y0 ? RectMm{x0, y0, x1 - x0, y1 - y0} : RectMm{};
}

// The layout on paper of one orientation.
BoardLayout LayOut(const BoardLayoutOptions& options, const Paper& paper) {
  BoardLayout layout;
  layout.options = options;
  layout.paper = paper;
  const double m = options.page_margin_mm, f = options.FootprintMm();
  const double pw = paper.width_mm - 2 * m, ph = paper.height_mm - 2 * m;
  const bool grid = options.layout == "grid";
  const bool one_sheet = options.table_width_mm <= 0;
  layout.canvas_width_mm = one_sheet ? pw : options.table_width_mm;
  layout.canvas_height_mm = one_sheet ? (grid ? ph - kTextStripMm : ph) : options.table_height_mm;
  const double w = layout.canvas_width_mm, h = layout.canvas_height_mm;
  const Tiling columns = TileAxis(w, pw, f), rows = TileAxis(h, ph, f);
  layout.columns = columns.count;
  layout.rows = rows.count;
  const std::vector<CanvasTag> tags = grid ? GridTags(w, h, f, columns, rows) : RingTags(w, h, f, columns, rows);

  std::map<std::pair<int, int>, std::vector<std::pair<int, CanvasTag>>> by_tile;  // (row, column) -> tags
  for (size_t i = 0; i < tags.size(); ++i) {
    const int id = options.first_id + int(i);
    by_tile[{rows.Of(tags[i].y), columns.Of(tags[i].x)}].push_back({id, tags[i]});
    layout.board.tags.push_back(WorldTag(id, tags[i], w, h, options.tag_size_mm));
  }
  std::map<std::pair<int, int>, int> numbers;
  for (const auto& [tile, unused] : by_tile) numbers[tile] = int(numbers.size()) + 1;
  const auto number_of = [&](int row, int column) {
    const auto it = numbers.find({row, column});
    return it == numbers.end() ? 0 : it->second;
  };
  const RectMm canvas{0, 0, w, h};
  const RectMm interior = grid && one_sheet ? RectMm{0, h, pw, kTextStripMm} : RectMm{f, f, w - 2 * f, h - 2 * f};
  for (const auto& [tile, placed] : by_tile) {
    BoardPage page;
    page.row = tile.first;
    page.column = tile.second;
    page.number = number_of(page.row, page.column);
    page.canvas_x_mm = columns.Start(page.column);
    page.canvas_y_mm = rows.Start(page.row);
    // Canvas millimetres -> this sheet's: its printable area starts at the margin.
    const auto on_page = [&](const RectMm& r) {
      return RectMm{r.x - page.canvas_x_mm + m, r.y - page.canvas_y_mm + m, r.w, r.h};
    };
    const RectMm canvas_tile{page.canvas_x_mm, page.canvas_y_mm, pw, ph};
    page.tile = on_page(Intersect(canvas, canvas_tile));
    page.text_area = on_page(Intersect(interior, canvas_tile));
    for (const auto& [id, t] : placed)
      page.tags.push_back({id, t.x - page.canvas_x_mm + m, t.y - page.canvas_y_mm + m, t.quarter_turns});
    page.left_page = number_of(page.row, page.column - 1);
    page.top_page = number_of(page.row - 1, page.column);
    page.right_page = number_of(page.row, page.column + 1);
    page.bottom_page = number_of(page.row + 1, page.column);
    layout.pages.push_back(page);
  }
  layout.board.family = options.family;
  layout.board.tag_size_m = options.tag_size_mm / 1000;
  layout.board.cell_size_m = options.CellMm() / 1000;
  layout.board.white_margin_m = 2 * options.CellMm() / 1000;
  return layout;
}

}  // namespace

Paper ParsePaper(const std::string& text) {
  const std::string name = Lower(text);
  if (name == "a4") return {"A4", 210, 297};
  if (name == "a3") return {"A3", 297, 420};
  if (name == "letter") return {"letter", 215.9, 279.4};
  double w = 0, h = 0;
  char tail = 0;
  if (std::sscanf(name.c_str(), "%lfx%lf%c", &w, &h, &tail) == 2 && w >= 50 && h >= 50 && w <= 5000 && h <= 5000)
    return {Mm(w) + "x" + Mm(h) + " mm", w, h};
  ThrowInputError("--paper", "'" + text + "' (expected A4, A3, letter or WxH in millimetres, 50 to 5000 each)");
}

std::vector<std::string> BoardLayoutOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(tag_size_mm >= 5 && tag_size_mm <= 1000))
    problems.push_back("tag size: " + Mm(tag_size_mm) + " mm (expected 5 to 1000)");
  if (black_cells < 3) problems.push_back("black_cells: " + std::to_string(black_cells) + " (expected at least 3)");
  if (layout != "table-border" && layout != "grid")
    problems.push_back("layout: '" + layout + "' (expected table-border or grid)");
  if (first_id < 0) problems.push_back("ids: from " + std::to_string(first_id) + " (expected 0 or more)");
  if (!(page_margin_mm >= 0 && 2 * page_margin_mm < std::min(paper.width_mm, paper.height_mm)))
    problems.push_back("page margin: " + Mm(page_margin_mm) + " mm (expected less than half the paper)");
  const bool table = table_width_mm > 0 || table_height_mm > 0;
  if (table && layout == "grid")
    problems.push_back("table: a grid is one sheet (expected no --table with --layout grid)");
  if (table && !(table_width_mm > 2 * FootprintMm() && table_height_mm > 2 * FootprintMm() && table_width_mm <= 20000 &&
                 table_height_mm <= 20000))
    problems.push_back("table: " + Mm(table_width_mm) + " x " + Mm(table_height_mm) + " mm (expected more than " +
                       Mm(2 * FootprintMm()) + " mm, two tags with their margins, on each side, and at most 20 m)");
  return problems;
}

BoardLayout MakeBoardLayout(const BoardLayoutOptions& options) {
  Problems problems("board");
  for (const std::string& p : options.Validate()) problems.Add("", p);
  problems.ThrowIfAny();
  BoardLayout best = LayOut(options, options.paper);
  // A board of several sheets may take fewer of them turned.
  if (options.table_width_mm > 0) {
    const Paper turned{options.paper.name + " landscape", options.paper.height_mm, options.paper.width_mm};
    BoardLayout other = LayOut(options, turned);
    if (other.pages.size() < best.pages.size()) best = std::move(other);
  }
  if (best.board.tags.empty())
    ThrowInputError("board", "no tag of " + Mm(options.tag_size_mm) + " mm (with its white margin, " +
                                 Mm(options.FootprintMm()) + " mm) fits on " + options.paper.name +
                                 " (expected a smaller --tag-size)");
  return best;
}

Board ScaleBoard(const Board& board, double factor) {
  Board out = board;
  out.tag_size_m *= factor;
  out.cell_size_m *= factor;
  out.white_margin_m *= factor;
  for (BoardTag& tag : out.tags) {
    tag.center = tag.center * factor;
    for (Vec3& c : tag.corners) c = c * factor;
  }
  return out;
}

}  // namespace nerfar
