// Strict JSON: parse with line/column errors, read objects key by key with
// every problem collected (as "file: /json/pointer: what (expected)"), and
// reject unknown keys so that a typo never silently becomes a default.
// nlohmann::json is only forward-declared here; include <nlohmann/json.hpp>
// in the .cpp files that build or walk documents.
#pragma once

#include <array>
#include <initializer_list>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "calib/core/error.h"

namespace nerfar {

using Json = nlohmann::json;

// Largest JSON file any reader accepts (datasets with thousands of frames fit).
inline constexpr size_t kMaxJsonBytes = size_t{64} << 20;

// InputError "source: line L, column C: what" on syntax errors.
Json ParseJson(const std::string& text, const std::string& source);
Json ReadJsonFile(const std::string& path);
// Pretty-printed, atomic.
void WriteJsonFile(const std::string& path, const Json& document);
std::string DumpJson(const Json& document, int indent = 2);

// A strict view of one JSON object. Every Get marks its key as known; Finish()
// reports the keys nobody asked for. Problems go into the shared list, so one
// pass over a file reports everything wrong with it.
class JsonObjectReader {
 public:
  // `pointer` is this object's JSON pointer ("" for the root).
  JsonObjectReader(const Json& value, std::string pointer, Problems& problems);

  bool valid() const { return object_ != nullptr; }
  bool Has(const char* key) const;
  // Keys that carry documentation only (e.g. "units", "note"): accepted, unread.
  void Allow(std::initializer_list<const char*> keys);

  // Required values: a problem is recorded (and a neutral value returned) if the
  // key is missing or has the wrong type or range.
  double Number(const char* key);
  double Number(const char* key, double min, double max);
  long long Integer(const char* key, long long min, long long max);
  // The same, also accepting a number with no fractional part (1080.0, as
  // instant-ngp writes image sizes).
  long long WholeNumber(const char* key, long long min, long long max);
  std::string String(const char* key);
  bool Bool(const char* key);
  std::vector<double> Numbers(const char* key, size_t expected_size = 0);  // 0: any size
  std::array<double, 3> Vec3(const char* key);
  // Row-major 4x4 matrix given as 4 arrays of 4 numbers.
  std::array<double, 16> Matrix4(const char* key);

  // Optional values.
  std::optional<double> OptionalNumber(const char* key);
  std::optional<double> OptionalNumber(const char* key, double min, double max);
  std::optional<std::string> OptionalString(const char* key);

  // Nested objects and arrays (nullptr with a problem when missing or mistyped).
  const Json* Object(const char* key, bool required = true);
  const Json* Array(const char* key, bool required = true);

  std::string PointerTo(const char* key) const;
  Problems& problems() { return problems_; }
  void Finish();

 private:
  const Json* Lookup(const char* key, bool required);

  const Json* object_ = nullptr;
  std::string pointer_;
  Problems& problems_;
  std::set<std::string> known_;
};

}  // namespace nerfar
