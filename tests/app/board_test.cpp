// `nerfar board` checked as a printer would be: the PDF rasterised at a known
// resolution by poppler's pdftoppm and the PNG read at the resolution its pHYs
// chunk states, every tag found by OpenCV's aruco detector (independent of our
// own) and compared with board.json: each id once, corners in board.json's
// order, the tag edge at the stated size, and all corners on one rigid map
// from board.json's metres to the sheet's millimetres (scale 1000, no turn).
// Multi-sheet boards per sheet; --printed-ruler; the bad-input paths.
#include "calib/board.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>

#include "calib/core/atomic_file.h"
#include "calib/core/image_io.h"
#include "tests/support/nerfar_command.h"
#include "tests/support/support.h"
#include "tracking/aruco_reference.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;
using Result = testing::CommandResult;
using testing::RunNerfar;

// Corner localisation of aruco with sub-pixel refinement on a clean raster is
// within half a pixel; the raster's own edges within half a pixel more. At
// 200 dpi a pixel is 0.127 mm: 0.25 mm holds both and is 1/40 of a 10 mm
// error nobody would accept (and a wrong cell or a turned tag is 3+ mm off).
constexpr double kCornerToleranceMm = 0.25;

struct SheetFit {
  int tags = 0;
  double scale = 0;         // sheet millimetres per board metre
  double rotation_rad = 0;  // of board.json's x axis on the sheet (y down, so board y flips)
  double worst_residual_mm = 0;
  double worst_edge_error_mm = 0;
};

// Fits sheet = s R(θ) F world + t (F flips y: board y points up the sheet)
// to every detected corner of the board's tags (Umeyama in 2-D), and reports
// the residuals and the tags' edge lengths against board.json's tag_size.
SheetFit FitSheet(const std::vector<TagDetection>& detections, const Board& board, double px_per_mm,
                  std::map<int, int>& seen) {
  std::vector<Vec2> world, sheet;
  SheetFit fit;
  for (const TagDetection& d : detections) {
    const BoardTag* tag = board.FindTag(d.id);
    if (tag == nullptr) continue;
    ++seen[d.id];
    ++fit.tags;
    for (int k = 0; k < 4; ++k) {
      world.push_back({tag->corners[k].x, -tag->corners[k].y});
      sheet.push_back({d.corners[k].x / px_per_mm, d.corners[k].y / px_per_mm});
      const Vec2& a = d.corners[k];
      const Vec2& b = d.corners[(k + 1) % 4];
      const double edge_mm = std::hypot(b.x - a.x, b.y - a.y) / px_per_mm;
      fit.worst_edge_error_mm = std::max(fit.worst_edge_error_mm, std::abs(edge_mm - board.tag_size_m * 1000));
    }
  }
  if (world.size() < 8) return fit;
  Vec2 mw, ms;
  for (size_t i = 0; i < world.size(); ++i) {
    mw.x += world[i].x / world.size(), mw.y += world[i].y / world.size();
    ms.x += sheet[i].x / world.size(), ms.y += sheet[i].y / world.size();
  }
  double a = 0, b = 0, norm = 0;  // Σ (w·s), Σ (w × s), Σ |w|²
  for (size_t i = 0; i < world.size(); ++i) {
    const double wx = world[i].x - mw.x, wy = world[i].y - mw.y, sx = sheet[i].x - ms.x, sy = sheet[i].y - ms.y;
    a += wx * sx + wy * sy;
    b += wx * sy - wy * sx;
    norm += wx * wx + wy * wy;
  }
  fit.rotation_rad = std::atan2(b, a);
  fit.scale = std::hypot(a, b) / norm;
  const double c = std::cos(fit.rotation_rad), s = std::sin(fit.rotation_rad);
  for (size_t i = 0; i < world.size(); ++i) {
    const double wx = world[i].x - mw.x, wy = world[i].y - mw.y;
    const double px = ms.x + fit.scale * (c * wx - s * wy), py = ms.y + fit.scale * (s * wx + c * wy);
    fit.worst_residual_mm = std::max(fit.worst_residual_mm, std::hypot(px - sheet[i].x, py - sheet[i].y));
  }
  return fit;
}

void ExpectSheetMatches(const SheetFit& fit, const std::string& what) {
  ASSERT_GE(fit.tags, 2) << what;
  EXPECT_NEAR(fit.scale, 1000.0, 1000.0 * 1e-3) << what;  // 0.1 %: 0.2 mm across an A4 sheet
  EXPECT_NEAR(fit.rotation_rad, 0.0, 1e-3) << what;
  EXPECT_LT(fit.worst_residual_mm, kCornerToleranceMm) << what;
  EXPECT_LT(fit.worst_edge_error_mm, 2 * kCornerToleranceMm) << what;  // two corners' errors
  std::printf("%s: %d tags, scale %.5f mm/mm, rotation %.2e rad, worst corner %.3f mm, worst edge %.3f mm\n",
              what.c_str(), fit.tags, fit.scale / 1000, fit.rotation_rad, fit.worst_residual_mm,
              fit.worst_edge_error_mm);
}

// The resolution a PNG states in its pHYs chunk (pixels per metre, unit 1), read from the bytes.
double PngDpi(const std::string& path) {
  const std::string bytes = ReadFileBytes(path);
  const size_t at = bytes.find("pHYs");
  if (at == std::string::npos || at + 13 > bytes.size()) return 0;
  const auto u32 = [&](size_t i) {
    return (std::uint32_t(std::uint8_t(bytes[i])) << 24) | (std::uint32_t(std::uint8_t(bytes[i + 1])) << 16) |
           (std::uint32_t(std::uint8_t(bytes[i + 2])) << 8) | std::uint32_t(std::uint8_t(bytes[i + 3]));
  };
  return bytes[at + 12] == 1 ? u32(at + 4) * 0.0254 : 0;
}

bool HavePdftoppm() { return std::system("pdftoppm -v > /dev/null 2>&1") == 0; }

// Rasterises every page of the PDF at `dpi` (grey PNGs) and returns their paths.
std::vector<std::string> RasterisePdf(const std::string& pdf, int dpi, const std::string& prefix) {
  const Result r = testing::RunCommand("pdftoppm -r " + std::to_string(dpi) + " -gray -png " + pdf + " " + prefix);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::vector<std::string> pages;
  for (const auto& entry : fs::directory_iterator(fs::path(prefix).parent_path()))
    if (entry.path().filename().string().rfind(fs::path(prefix).filename().string() + "-", 0) == 0)
      pages.push_back(entry.path().string());
  std::sort(pages.begin(), pages.end());
  return pages;
}

class BoardCommand : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!ArucoAvailable()) GTEST_SKIP() << "OpenCV's aruco module is not in this build";
  }
  testing::TempDir tmp_;
};

TEST_F(BoardCommand, PdfAndPngTagsAreWhereBoardJsonSays) {
  const std::string dir = tmp_.File("board");
  const Result r = RunNerfar("board -o " + dir + " --paper A4 --tag-size 30 --ids 5 --dpi 200");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Board board = ReadBoard(dir + "/board.json");
  ASSERT_GE(board.tags.size(), 12u);
  EXPECT_EQ(board.tags.front().id, 5);
  EXPECT_NEAR(board.tag_size_m, 0.030, 1e-12);
  // The PNG, at the resolution it states.
  const std::string png = dir + "/board_sheet1_200dpi.png";
  EXPECT_NEAR(PngDpi(png), 200.0, 0.01);
  std::map<int, int> seen;
  ExpectSheetMatches(FitSheet(DetectWithAruco(ReadImage8(png), ArucoRefine::kSubpix), board, 200 / 25.4, seen), "PNG");
  for (const BoardTag& tag : board.tags) EXPECT_EQ(seen[tag.id], 1) << "id " << tag.id << " in the PNG";
  // The PDF, rasterised by poppler.
  if (!HavePdftoppm()) GTEST_SKIP() << "pdftoppm (poppler-utils) is not installed";
  const std::vector<std::string> pages = RasterisePdf(dir + "/board.pdf", 200, tmp_.File("pdf"));
  ASSERT_EQ(pages.size(), 1u);
  seen.clear();
  ExpectSheetMatches(FitSheet(DetectWithAruco(ReadImage8(pages[0]), ArucoRefine::kSubpix), board, 200 / 25.4, seen),
                     "PDF");
  for (const BoardTag& tag : board.tags) EXPECT_EQ(seen[tag.id], 1) << "id " << tag.id << " in the PDF";
}

TEST_F(BoardCommand, GridCalibrationSheet) {
  const std::string dir = tmp_.File("grid");
  const Result r = RunNerfar("board -o " + dir + " --layout grid --tag-size 20 --paper letter --dpi 150");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Board board = ReadBoard(dir + "/board.json");
  EXPECT_GE(board.tags.size(), 30u);
  std::map<int, int> seen;
  ExpectSheetMatches(FitSheet(DetectWithAruco(ReadImage8(dir + "/board_sheet1_150dpi.png"), ArucoRefine::kSubpix),
                              board, 150 / 25.4, seen),
                     "grid PNG");
  for (const BoardTag& tag : board.tags) EXPECT_EQ(seen[tag.id], 1) << "id " << tag.id;
}

TEST_F(BoardCommand, SeveralSheetsTileATable) {
  if (!HavePdftoppm()) GTEST_SKIP() << "pdftoppm (poppler-utils) is not installed";
  const std::string dir = tmp_.File("table");
  const Result r = RunNerfar("board -o " + dir + " --table 600x400 --tag-size 40 --dpi 100");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Board board = ReadBoard(dir + "/board.json");
  const std::vector<std::string> pages = RasterisePdf(dir + "/board.pdf", 150, tmp_.File("pdf"));
  ASSERT_GE(pages.size(), 2u);
  std::map<int, int> seen;
  for (size_t p = 0; p < pages.size(); ++p) {
    // Each sheet holds its tags rigidly at scale (how the sheets join is
    // printed on them; a sheet with one tag has nothing relative to check).
    const SheetFit fit = FitSheet(DetectWithAruco(ReadImage8(pages[p]), ArucoRefine::kSubpix), board, 150 / 25.4, seen);
    if (fit.tags >= 2) ExpectSheetMatches(fit, "sheet " + std::to_string(p + 1));
  }
  for (const BoardTag& tag : board.tags) EXPECT_EQ(seen[tag.id], 1) << "id " << tag.id << " on exactly one sheet";
  // The ring: every tag's printed up points away from the board's centre.
  for (const BoardTag& tag : board.tags) EXPECT_GT(Dot(tag.up_direction, tag.center), 0.0) << "id " << tag.id;
}

TEST_F(BoardCommand, PrintedRulerRescalesBoardJson) {
  const std::string dir = tmp_.File("b");
  ASSERT_EQ(RunNerfar("board -o " + dir + " --dpi 72").exit_code, 0);
  const Board printed = ReadBoard(dir + "/board.json");
  const Result r = RunNerfar("board -o " + dir + " --printed-ruler 99");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Board scaled = ReadBoard(dir + "/board.json");
  EXPECT_NEAR(scaled.tag_size_m, printed.tag_size_m * 0.99, 1e-12);
  EXPECT_NEAR(scaled.tags[3].corners[2].x, printed.tags[3].corners[2].x * 0.99, 1e-12);
}

TEST(BoardCommandInput, BadInputExitsTwoNamingIt) {
  struct Case {
    const char* args;
    const char* says;
  };
  testing::TempDir tmp;
  const std::string o = " -o " + tmp.File("x");
  for (const Case& c :
       {Case{"board", "missing -o DIR (required)"}, Case{"board --paper A7", "--paper"},
        Case{"board --family tag99h9", "tag family"}, Case{"board --family tagStandard41h12", "classic family"},
        Case{"board --tag-size 400", "no tag of 400 mm"}, Case{"board --ids 585", "not in tag36h11"},
        Case{"board --layout spiral", "layout"}, Case{"board --table 100x100 --tag-size 40", "table"}}) {
    const Result r =
        RunNerfar(std::string(c.args) +
                  (std::string(c.args).find("-o") == std::string::npos && std::string(c.args) != "board" ? o : ""));
    EXPECT_EQ(r.exit_code, 2) << c.args << ": " << r.output;
    EXPECT_NE(r.output.find(c.says), std::string::npos) << c.args << ": " << r.output;
  }
}

}  // namespace
}  // namespace nerfar
