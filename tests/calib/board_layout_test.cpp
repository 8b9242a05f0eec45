// calib/board_layout: the sheets of a board against what a user does with
// them: each tag with its white margin inside one sheet's printable tile and
// clear of every other; sheets joined as they say (a cut edge on its
// neighbour's line, tiles' edges meeting) put every tag where board.json
// says relative to every other; the ring's tags point away from the centre;
// paper names; a scaled board.
#include "calib/board_layout.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "calib/core/error.h"

namespace nerfar {
namespace {

struct Placed {
  const BoardPage* page;
  PlacedTag tag;
};

std::map<int, Placed> ById(const BoardLayout& layout) {
  std::map<int, Placed> out;
  for (const BoardPage& page : layout.pages)
    for (const PlacedTag& tag : page.tags) out[tag.id] = {&page, tag};
  return out;
}

BoardLayoutOptions TableOptions() {
  BoardLayoutOptions o;
  o.table_width_mm = 1200;
  o.table_height_mm = 800;
  o.tag_size_mm = 60;
  return o;
}

TEST(BoardLayout, EveryTagWithItsMarginInsideOneTileAndClearOfTheOthers) {
  for (const BoardLayoutOptions& options : {BoardLayoutOptions{}, TableOptions()}) {
    const BoardLayout layout = MakeBoardLayout(options);
    const double half = options.FootprintMm() / 2;
    const std::map<int, Placed> tags = ById(layout);
    ASSERT_EQ(tags.size(), layout.board.tags.size());
    for (const auto& [id, p] : tags) {
      const RectMm& t = p.page->tile;
      EXPECT_GE(p.tag.x_mm - half, t.x - 1e-9) << id;
      EXPECT_LE(p.tag.x_mm + half, t.x + t.w + 1e-9) << id;
      EXPECT_GE(p.tag.y_mm - half, t.y - 1e-9) << id;
      EXPECT_LE(p.tag.y_mm + half, t.y + t.h + 1e-9) << id;
    }
    // Footprints of two tags do not overlap (board.json centres, millimetres).
    for (size_t i = 0; i < layout.board.tags.size(); ++i)
      for (size_t j = i + 1; j < layout.board.tags.size(); ++j) {
        const Vec3 d = (layout.board.tags[i].center - layout.board.tags[j].center) * 1000.0;
        EXPECT_GE(std::max(std::abs(d.x), std::abs(d.y)), options.FootprintMm() - 1e-9) << i << " " << j;
      }
  }
}

TEST(BoardLayout, SheetsJoinedAsTheySayPutTagsWhereBoardJsonSays) {
  // Sheet B laid onto its left neighbour A: B's tile starts where A's ends
  // (the cut edge on the line), at the same height (same row). Onto its top
  // neighbour likewise. Following those joins from sheet to sheet, every
  // pair of tags on joined sheets is as far apart as board.json says
  // (board y runs up the sheet).
  const BoardLayout layout = MakeBoardLayout(TableOptions());
  ASSERT_GT(layout.pages.size(), 4u);
  std::map<int, const BoardPage*> by_number;
  for (const BoardPage& page : layout.pages) by_number[page.number] = &page;
  const std::map<int, Placed> tags = ById(layout);
  int pairs = 0;
  for (const auto& [id_b, b] : tags)
    for (const auto& [id_a, a] : tags) {
      const bool left = b.page->left_page == a.page->number, above = b.page->top_page == a.page->number;
      if (!left && !above) continue;
      // B's position in A's sheet coordinates after the join.
      const RectMm &ta = a.page->tile, &tb = b.page->tile;
      const double x = left ? b.tag.x_mm - tb.x + ta.x + ta.w : b.tag.x_mm - tb.x + ta.x;
      const double y = left ? b.tag.y_mm - tb.y + ta.y : b.tag.y_mm - tb.y + ta.y + ta.h;
      const BoardTag* wa = layout.board.FindTag(id_a);
      const BoardTag* wb = layout.board.FindTag(id_b);
      EXPECT_NEAR(x - a.tag.x_mm, 1000 * (wb->center.x - wa->center.x), 1e-9) << id_a << " -> " << id_b;
      EXPECT_NEAR(y - a.tag.y_mm, -1000 * (wb->center.y - wa->center.y), 1e-9) << id_a << " -> " << id_b;
      ++pairs;
    }
  EXPECT_GT(pairs, 20);
}

TEST(BoardLayout, RingTagsPointAwayFromTheCentreAndCornersAreInOrder) {
  const BoardLayout layout = MakeBoardLayout(BoardLayoutOptions{});
  ASSERT_GE(layout.board.tags.size(), 12u);
  for (const BoardTag& tag : layout.board.tags) {
    EXPECT_GT(Dot(tag.up_direction, tag.center), 0.0) << tag.id;
    // board.json's order: TL, TR, BR, BL of the upright tag; up from BL to TL.
    EXPECT_NEAR(Length(tag.corners[0] - tag.corners[3] - tag.up_direction * 0.03), 0.0, 1e-12) << tag.id;
    EXPECT_NEAR(Length(tag.corners[1] - tag.corners[0] - Cross(tag.up_direction, Vec3{0, 0, 1}) * 0.03), 0.0, 1e-12)
        << tag.id;
  }
  EXPECT_EQ(layout.board.tags.front().id, 0);
  EXPECT_EQ(layout.board.tags.back().id, int(layout.board.tags.size()) - 1);
}

TEST(BoardLayout, PapersAndBadOptions) {
  EXPECT_EQ(ParsePaper("a4").width_mm, 210.0);
  EXPECT_EQ(ParsePaper("Letter").height_mm, 279.4);
  EXPECT_EQ(ParsePaper("300x400").width_mm, 300.0);
  EXPECT_THROW(ParsePaper("A7"), InputError);
  EXPECT_THROW(ParsePaper("300x400mm"), InputError);
  BoardLayoutOptions o;
  o.tag_size_mm = 150;  // 225 mm with its margins: wider than an A4 sheet prints
  EXPECT_THROW(MakeBoardLayout(o), InputError);
  o = TableOptions();
  o.layout = "grid";
  EXPECT_THROW(MakeBoardLayout(o), InputError);
}

TEST(BoardLayout, ScaledBoardScalesEveryLength) {
  const Board board = MakeBoardLayout(BoardLayoutOptions{}).board;
  const Board scaled = ScaleBoard(board, 0.99);
  EXPECT_NEAR(scaled.tag_size_m, 0.99 * board.tag_size_m, 1e-15);
  EXPECT_NEAR(scaled.tags[5].corners[1].y, 0.99 * board.tags[5].corners[1].y, 1e-15);
  EXPECT_EQ(scaled.tags[5].up_direction, board.tags[5].up_direction);
}

}  // namespace
}  // namespace nerfar
