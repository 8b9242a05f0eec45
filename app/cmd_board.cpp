// nerfar board -o DIR [--paper P] [--tag-size MM] [--family F] [--layout L] [--ids FROM] [--table WxH] [--dpi D]
// The first step of a session: a tag board to print. Joins the layout
// (calib/board_layout.h), the families' bit patterns (tracking's TagBitmap)
// and the printers of app/board_print.h: DIR/board.pdf (vector, exact scale),
// DIR/board_sheet<N>_<D>dpi.png and DIR/board.json. --printed-ruler rewrites
// board.json at the scale the sheet came out of the printer.
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>

#include "app/board_print.h"
#include "app/cli.h"
#include "app/commands.h"
#include "calib/board.h"
#include "calib/board_layout.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "tracking/tag_detector.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;

std::string Number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g", v);
  return buffer;
}

struct BoardJob {
  std::string output, paper = "A4", family = "tag36h11", layout = "table-border", table;
  double tag_size_mm = 30, dpi = 300, printed_ruler_mm = 0;
  int first_id = 0;
};

// "1200x800" (millimetres) -> width, height.
void ParseTable(const std::string& text, BoardLayoutOptions& options) {
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lfx%lf%c", &options.table_width_mm, &options.table_height_mm, &tail) != 2)
    ThrowInputError("--table", "'" + text + "' (expected WxH in millimetres, e.g. 1200x800)");
}

// Bitmaps of every id on the board; InputError for ids the family lacks and
// for families whose data bits lie outside the black square (the layout's
// white margin assumes the classic families' one-cell white border).
std::map<int, Image8> TagBitmaps(const BoardLayout& layout) {
  std::map<int, Image8> bitmaps;
  for (const BoardTag& tag : layout.board.tags) {
    Image8 bitmap = TagBitmap(layout.options.family, tag.id);
    if (bitmap.width != layout.options.black_cells + 2)
      ThrowInputError("--family", layout.options.family +
                                      " has data cells outside its black square (expected a classic family: "
                                      "tag36h11, tag25h9 or tag16h5)");
    bitmaps.emplace(tag.id, std::move(bitmap));
  }
  return bitmaps;
}

// The command as given, without --printed-ruler, for the sheet's instruction.
std::string CommandLine(const CommandArgs& args) {
  std::string line = "nerfar board";
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--printed-ruler") {
      ++i;
      continue;
    }
    line += " " + args[i];
  }
  return line;
}

}  // namespace

int RunBoard(const CommandArgs& args) {
  BoardJob job;
  ArgParser parser("board", "A tag board to print: a vector PDF at exact scale, PNGs, and its board.json.");
  parser.Option("-o", &job.output, "DIR", "folder to write board.pdf, board_sheet<N>_<D>dpi.png, board.json");
  parser.Required("-o");
  parser.Option("--paper", &job.paper, "P", "A4 (default), letter, A3, or WxH in millimetres");
  parser.Option("--tag-size", &job.tag_size_mm, "MM", "edge of each tag's black square (default 30)");
  parser.Option("--family", &job.family, "F", "tag36h11 (default), tag25h9 or tag16h5");
  parser.Option("--layout", &job.layout, "L",
                "table-border (default: tags in a ring, objects in the middle) or grid (a calibration sheet)");
  parser.Option("--ids", &job.first_id, "FROM", "first tag id; the others follow (default 0)");
  parser.Option("--table", &job.table, "WxH",
                "table-border over a larger table, in millimetres (e.g. 1200x800): tiled over several sheets");
  parser.Option("--dpi", &job.dpi, "D", "resolution of the PNGs (default 300)");
  parser.Option("--printed-ruler", &job.printed_ruler_mm, "MM",
                "the length the sheet's ruler measured once printed: rewrites board.json at that scale");
  parser.Epilog(
      "Print the PDF at 100 % (actual size) and measure the ruler on the sheet. Each tag keeps a white margin of two\n"
      "cells. Several sheets (--table) are cut and laid edge to edge as each sheet says.\n"
      "Example: nerfar board -o myboard --paper A4 --tag-size 30\n"
      "         nerfar board -o calib --layout grid --tag-size 20 --ids 100");
  if (!parser.Parse(args)) return 0;
  Problems usage("nerfar board");
  if (!(job.dpi >= 72 && job.dpi <= 1200)) usage.Add("--dpi", Number(job.dpi) + " (expected 72 to 1200)");
  if (job.printed_ruler_mm < 0) usage.Add("--printed-ruler", "must be > 0 (millimetres)");
  usage.ThrowIfAny();

  BoardLayoutOptions options;
  options.paper = ParsePaper(job.paper);
  options.tag_size_mm = job.tag_size_mm;
  options.family = job.family;
  options.black_cells = TagBlackSquareCells(job.family);
  options.layout = job.layout;
  options.first_id = job.first_id;
  if (!job.table.empty()) ParseTable(job.table, options);
  const BoardLayout layout = MakeBoardLayout(options);
  const std::map<int, Image8> bitmaps = TagBitmaps(layout);
  MakeDirectories(job.output);
  const fs::path dir(job.output);

  if (job.printed_ruler_mm > 0) {
    const double nominal = RulerLengthMm(layout);
    const double factor = job.printed_ruler_mm / nominal;
    WriteBoard((dir / "board.json").string(), ScaleBoard(layout.board, factor));
    std::printf("board.json rewritten at the printed scale: ruler %g mm for %g mm, lengths x %.4f\n",
                job.printed_ruler_mm, nominal, factor);
    return 0;
  }
  const std::vector<Sheet> sheets = DrawBoardSheets(layout, bitmaps, CommandLine(args));
  WriteSheetsPdf((dir / "board.pdf").string(), sheets);
  for (size_t i = 0; i < sheets.size(); ++i) {
    char name[64];
    std::snprintf(name, sizeof name, "board_sheet%zu_%gdpi.png", i + 1, job.dpi);
    WritePngWithDpi((dir / name).string(), RasteriseSheet(sheets[i], job.dpi), job.dpi);
  }
  WriteBoard((dir / "board.json").string(), layout.board);
  std::printf(
      "board: %zu %s tags of %g mm (ids %d-%d), %s, on %zu %s sheet%s: %s/board.pdf, %zu PNG at %g dpi, "
      "board.json\n",
      layout.board.tags.size(), options.family.c_str(), options.tag_size_mm, options.first_id,
      options.first_id + int(layout.board.tags.size()) - 1, options.layout.c_str(), sheets.size(),
      layout.paper.name.c_str(), sheets.size() == 1 ? "" : "s", job.output.c_str(), sheets.size(), job.dpi);
  LogInfo("board: print board.pdf at 100 % and measure its ruler (" + Number(RulerLengthMm(layout)) +
          " mm); if it differs, run the same command with --printed-ruler MEASURED_MM");
  return 0;
}

}  // namespace nerfar
