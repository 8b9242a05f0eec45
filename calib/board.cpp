#include "calib/board.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>

#include "calib/core/json.h"

namespace nerfar {
namespace {

// AprilTag families a detector may be asked for.
const std::set<std::string>& KnownFamilies() {
  static const std::set<std::string> families = {"tag16h5",          "tag25h9",         "tag36h11",
                                                 "tagCircle21h7",    "tagCircle49h12",  "tagCustom48h12",
                                                 "tagStandard41h12", "tagStandard52h13"};
  return families;
}

constexpr long long kMaxTagId = 1 << 20;
constexpr size_t kMaxTags = 100000;

std::string FormatNumber(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.6g", v);
  return buffer;
}

Vec3 ToVec3(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }
Json ToJson(const Vec3& v) { return Json::array({v.x, v.y, v.z}); }

// Geometry checks of one tag against the board's tag size. Tolerances: the
// files store float-rounded metres, so 0.1 mm (or 0.1% of the tag) is far
// above rounding and far below any real layout error.
void CheckTagGeometry(const BoardTag& tag, double tag_size, const std::string& pointer, Problems& problems) {
  const double tolerance = std::max(1e-4, 1e-3 * tag_size);
  for (int k = 0; k < 4; ++k) {
    const double edge = Length(tag.corners[(k + 1) % 4] - tag.corners[k]);
    if (tag_size > 0 && std::abs(edge - tag_size) > tolerance)
      problems.Add(pointer + "/corners", "edge from corner " + std::to_string(k) + " to " +
                                             std::to_string((k + 1) % 4) + " is " + FormatNumber(edge) +
                                             " m (expected tag_size " + FormatNumber(tag_size) + " m)");
  }
  const double d0 = Length(tag.corners[2] - tag.corners[0]);
  const double d1 = Length(tag.corners[3] - tag.corners[1]);
  if (std::abs(d0 - d1) > tolerance)
    problems.Add(pointer + "/corners", "diagonals are " + FormatNumber(d0) + " and " + FormatNumber(d1) +
                                           " m (expected a square: equal diagonals)");
  const Vec3 mean = (tag.corners[0] + tag.corners[1] + tag.corners[2] + tag.corners[3]) * 0.25;
  if (Length(mean - tag.center) > tolerance)
    problems.Add(pointer + "/center", "is " + FormatNumber(Length(mean - tag.center)) +
                                          " m from the corners' mean (expected the centre of the square)");
  const double up_length = Length(tag.up_direction);
  if (std::abs(up_length - 1) > 1e-3) {
    problems.Add(pointer + "/up_direction", "has length " + FormatNumber(up_length) + " (expected a unit vector)");
  } else {
    // Printed up runs from the bottom-left corner (3) to the top-left one (0).
    const Vec3 left_edge = Normalized(tag.corners[0] - tag.corners[3]);
    if (Dot(left_edge, tag.up_direction) < 0.999)
      problems.Add(pointer + "/up_direction",
                   "does not point from the bottom-left corner to the top-left corner (expected corners in the order "
                   "top-left, top-right, bottom-right, bottom-left)");
  }
}

}  // namespace

const BoardTag* Board::FindTag(int id) const {
  for (const BoardTag& tag : tags)
    if (tag.id == id) return &tag;
  return nullptr;
}

Board ReadBoard(const std::string& path) {
  const Json doc = ReadJsonFile(path);
  Problems problems(path);
  Board board;
  JsonObjectReader root(doc, "", problems);
  root.Allow({"units", "note", "notes", "comment", "corner_order", "orientation", "tag_size_definition"});
  if (root.valid()) {
    board.family = root.String("family");
    if (root.Has("family") && doc["family"].is_string() && !KnownFamilies().count(board.family))
      problems.Add("/family", "is \"" + board.family + "\" (expected an AprilTag family such as \"tag36h11\")");
    board.tag_size_m = root.Number("tag_size", 1e-4, 100.0);
    board.cell_size_m = root.OptionalNumber("cell_size", 1e-6, 100.0).value_or(0.0);
    board.white_margin_m = root.OptionalNumber("white_margin", 0.0, 100.0).value_or(0.0);
    std::optional<std::vector<long long>> ids;
    if (const Json* ids_json = root.Array("ids", false)) {
      ids.emplace();
      for (size_t i = 0; i < ids_json->size() && i < kMaxTags; ++i) {
        const Json& id = (*ids_json)[i];
        if (!id.is_number_integer()) {
          problems.Add("/ids/" + std::to_string(i), std::string("is ") + id.type_name() + " (expected an integer)");
        } else {
          ids->push_back(id.get<long long>());
        }
      }
    }
    if (const Json* tags = root.Array("tags")) {
      if (tags->empty()) problems.Add("/tags", "is empty (expected at least one tag)");
      if (tags->size() > kMaxTags) {
        problems.Add("/tags", "has " + std::to_string(tags->size()) + " tags (expected at most " +
                                  std::to_string(kMaxTags) + ")");
      } else {
        std::set<int> seen;
        for (size_t i = 0; i < tags->size(); ++i) {
          const std::string pointer = "/tags/" + std::to_string(i);
          JsonObjectReader item((*tags)[i], pointer, problems);
          item.Allow({"note", "comment"});
          const size_t before = problems.items().size();
          BoardTag tag;
          tag.id = static_cast<int>(item.Integer("id", 0, kMaxTagId));
          if (item.valid() && item.Has("id") && !seen.insert(tag.id).second)
            problems.Add(pointer + "/id", "is " + std::to_string(tag.id) + " again (expected unique ids)");
          tag.center = ToVec3(item.Vec3("center"));
          tag.up_direction = ToVec3(item.Vec3("up_direction"));
          item.OptionalNumber("yaw_deg", -720.0, 720.0);
          if (const Json* corners = item.Array("corners")) {
            if (corners->size() != 4) {
              problems.Add(pointer + "/corners",
                           "has " + std::to_string(corners->size()) + " entries (expected 4 corners)");
            } else {
              for (size_t k = 0; k < 4; ++k) {
                const Json& c = (*corners)[k];
                bool ok = c.is_array() && c.size() == 3;
                for (size_t j = 0; ok && j < 3; ++j) ok = c[j].is_number() && std::isfinite(c[j].get<double>());
                if (!ok) {
                  problems.Add(pointer + "/corners/" + std::to_string(k), "is not a point (expected [x, y, z] metres)");
                } else {
                  tag.corners[k] = {c[0].get<double>(), c[1].get<double>(), c[2].get<double>()};
                }
              }
            }
          }
          item.Finish();
          if (problems.items().size() == before) CheckTagGeometry(tag, board.tag_size_m, pointer, problems);
          board.tags.push_back(tag);
        }
      }
    }
    if (ids.has_value() && problems.empty()) {
      std::vector<long long> tag_ids;
      for (const BoardTag& tag : board.tags) tag_ids.push_back(tag.id);
      std::vector<long long> listed = *ids;
      std::sort(tag_ids.begin(), tag_ids.end());
      std::sort(listed.begin(), listed.end());
      if (tag_ids != listed) problems.Add("/ids", "does not list the ids of /tags (expected the same ids)");
    }
    root.Finish();
  }
  problems.ThrowIfAny();
  return board;
}

void WriteBoard(const std::string& path, const Board& board) {
  Json doc = Json::object();
  doc["family"] = board.family;
  doc["tag_size"] = board.tag_size_m;
  if (board.cell_size_m > 0) doc["cell_size"] = board.cell_size_m;
  if (board.white_margin_m > 0) doc["white_margin"] = board.white_margin_m;
  Json ids = Json::array();
  Json tags = Json::array();
  for (const BoardTag& tag : board.tags) {
    ids.push_back(tag.id);
    Json corners = Json::array();
    for (const Vec3& c : tag.corners) corners.push_back(ToJson(c));
    tags.push_back(Json{{"id", tag.id},
                        {"center", ToJson(tag.center)},
                        {"up_direction", ToJson(tag.up_direction)},
                        {"corners", corners}});
  }
  doc["ids"] = ids;
  doc["tags"] = tags;
  WriteJsonFile(path, doc);
}

}  // namespace nerfar
