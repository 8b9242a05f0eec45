#include "calib/core/option_fields.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <nlohmann/json.hpp>

#include "calib/core/error.h"
#include "calib/core/json.h"

namespace nerfar {
namespace {

// The whole text as one finite number, or false.
bool ParseNumber(const std::string& text, double* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *value = std::strtod(text.c_str(), &end);
  return *end == '\0' && errno == 0 && std::isfinite(*value);
}

// A whole number in [low, high] (both exactly representable as doubles).
bool ParseWhole(const std::string& text, double low, double high, double* value) {
  return ParseNumber(text, value) && *value == std::floor(*value) && *value >= low && *value <= high;
}

// "a, b or c".
std::string ChoiceList(const std::vector<const char*>& names) {
  std::string list;
  for (size_t i = 0; i < names.size(); ++i)
    list += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + std::string(names[i]);
  return list;
}

// What a field's values are, as an error names them.
std::string Expected(const OptionField& f) {
  switch (f.kind) {
    case OptionField::kInt:
      return "a whole number";
    case OptionField::kU64:
      return "a whole number >= 0";
    case OptionField::kBool:
      return "true or false";
    case OptionField::kChoice:
      return ChoiceList(f.choices);
    default:
      return "a number";
  }
}

// Parses `text` into the field; false (the field untouched) when it is not of its kind.
bool SetField(const OptionField& f, const std::string& text) {
  double v = 0;
  switch (f.kind) {
    case OptionField::kInt:
      if (!ParseWhole(text, std::numeric_limits<int>::min(), std::numeric_limits<int>::max(), &v)) return false;
      *static_cast<int*>(f.ptr) = static_cast<int>(v);
      return true;
    case OptionField::kU64: {
      // Digits alone are read exactly (seeds above 2^53); otherwise a whole number such as 1e6.
      uint64_t whole = 0;
      const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), whole);
      if (!text.empty() && error == std::errc() && end == text.data() + text.size()) {
        *static_cast<uint64_t*>(f.ptr) = whole;
        return true;
      }
      if (!ParseWhole(text, 0, 9007199254740992.0, &v)) return false;
      *static_cast<uint64_t*>(f.ptr) = static_cast<uint64_t>(v);
      return true;
    }
    case OptionField::kDouble:
      if (!ParseNumber(text, &v)) return false;
      *static_cast<double*>(f.ptr) = v;
      return true;
    case OptionField::kFloat:
      if (!ParseNumber(text, &v) || std::abs(v) > std::numeric_limits<float>::max()) return false;
      *static_cast<float*>(f.ptr) = static_cast<float>(v);
      return true;
    case OptionField::kBool:
      if (text != "true" && text != "false") return false;
      *static_cast<bool*>(f.ptr) = text == "true";
      return true;
    case OptionField::kChoice:
      for (size_t i = 0; i < f.choices.size(); ++i) {
        if (text != f.choices[i]) continue;
        f.set_choice(f.ptr, static_cast<int>(i));
        return true;
      }
      return false;
  }
  return false;
}

// The shortest decimal that reads back as `value` (as a float), as a double:
// JSON numbers are doubles, and the float's exact double value would print
// all its binary digits.
double ShortestDecimal(float value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::strtod(std::string(buffer, result.ptr).c_str(), nullptr);
}

}  // namespace

void SetOptionField(const std::vector<OptionField>& fields, const std::string& key_value, const std::string& source) {
  const size_t eq = key_value.find('=');
  if (eq == std::string::npos) ThrowInputError(source + " " + key_value, "has no '=' (expected key=value)");
  const std::string key = key_value.substr(0, eq), value = key_value.substr(eq + 1);
  for (const OptionField& f : fields) {
    if (key != f.name) continue;
    if (!SetField(f, value))
      ThrowInputError(source + " " + key_value,
                      "'" + value + "' is not a valid value of " + key + " (expected " + Expected(f) + ")");
    return;
  }
  std::string known;
  for (const OptionField& f : fields) known += (known.empty() ? "" : ", ") + std::string(f.name);
  ThrowInputError(source + " " + key_value, "unknown option '" + key + "' (expected one of: " + known + ")");
}

std::string OptionFieldsJson(const std::vector<OptionField>& fields) {
  Json doc = Json::object();
  for (const OptionField& f : fields) {
    switch (f.kind) {
      case OptionField::kInt:
        doc[f.name] = *static_cast<const int*>(f.ptr);
        break;
      case OptionField::kDouble:
        doc[f.name] = *static_cast<const double*>(f.ptr);
        break;
      case OptionField::kFloat:
        doc[f.name] = ShortestDecimal(*static_cast<const float*>(f.ptr));
        break;
      case OptionField::kBool:
        doc[f.name] = *static_cast<const bool*>(f.ptr);
        break;
      case OptionField::kU64:
        doc[f.name] = *static_cast<const uint64_t*>(f.ptr);
        break;
      case OptionField::kChoice:
        doc[f.name] = f.choices.at(f.get_choice(f.ptr));
        break;
    }
  }
  return doc.dump();
}

}  // namespace nerfar
