#include "calib/core/json.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "calib/core/atomic_file.h"

namespace nerfar {
namespace {

std::string EscapePointerToken(const std::string& key) {
  std::string out;
  for (char c : key) {
    if (c == '~') {
      out += "~0";
    } else if (c == '/') {
      out += "~1";
    } else {
      out += c;
    }
  }
  return out;
}

const char* TypeName(const Json& value) { return value.type_name(); }

}  // namespace

Json ParseJson(const std::string& text, const std::string& source) {
  // Locate the error by line and column ourselves: nlohmann reports a byte offset.
  try {
    return Json::parse(text, nullptr, /*allow_exceptions=*/true, /*ignore_comments=*/false);
  } catch (const Json::exception& e) {
    // Syntax errors carry a byte offset; others (a number out of range,
    // bad UTF-8) are reported at the end of what was read.
    const auto* syntax = dynamic_cast<const Json::parse_error*>(&e);
    const size_t byte = syntax != nullptr ? syntax->byte : text.size();
    size_t line = 1, column = 1;
    for (size_t i = 0; i + 1 < byte && i < text.size(); ++i) {
      if (text[i] == '\n') {
        ++line;
        column = 1;
      } else {
        ++column;
      }
    }
    std::string what = e.what();
    const size_t colon = what.rfind(": ");
    if (colon != std::string::npos) what = what.substr(colon + 2);
    ThrowInputError(source, "line " + std::to_string(line) + ", column " + std::to_string(column) + ": invalid JSON (" +
                                what + ")");
  }
}

Json ReadJsonFile(const std::string& path) { return ParseJson(ReadFileBytes(path, kMaxJsonBytes), path); }

std::string DumpJson(const Json& document, int indent) { return document.dump(indent) + "\n"; }

void WriteJsonFile(const std::string& path, const Json& document) { WriteFileAtomic(path, DumpJson(document)); }

JsonObjectReader::JsonObjectReader(const Json& value, std::string pointer, Problems& problems)
    : pointer_(std::move(pointer)), problems_(problems) {
  if (value.is_object()) {
    object_ = &value;
  } else {
    problems_.Add(pointer_.empty() ? "/" : pointer_, std::string("is ") + TypeName(value) + " (expected an object)");
  }
}

std::string JsonObjectReader::PointerTo(const char* key) const { return pointer_ + "/" + EscapePointerToken(key); }

bool JsonObjectReader::Has(const char* key) const { return object_ != nullptr && object_->contains(key); }

void JsonObjectReader::Allow(std::initializer_list<const char*> keys) {
  for (const char* key : keys) known_.insert(key);
}

const Json* JsonObjectReader::Lookup(const char* key, bool required) {
  known_.insert(key);
  if (object_ == nullptr) return nullptr;
  const auto it = object_->find(key);
  if (it == object_->end()) {
    if (required) problems_.Add(PointerTo(key), "missing");
    return nullptr;
  }
  return &*it;
}

double JsonObjectReader::Number(const char* key) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return 0.0;
  if (!value->is_number()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected a number)");
    return 0.0;
  }
  const double number = value->get<double>();
  if (!std::isfinite(number)) {
    problems_.Add(PointerTo(key), "is not finite (expected a finite number)");
    return 0.0;
  }
  return number;
}

double JsonObjectReader::Number(const char* key, double min, double max) {
  const bool present = Has(key);
  const size_t problems_before = problems_.items().size();
  const double number = Number(key);
  // A mistyped value is reported once, not again as out of range.
  if (present && problems_.items().size() == problems_before && (number < min || number > max))
    problems_.Add(PointerTo(key), "is " + std::to_string(number) + " (expected " + std::to_string(min) + " to " +
                                      std::to_string(max) + ")");
  return number;
}

long long JsonObjectReader::Integer(const char* key, long long min, long long max) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return min;
  if (!value->is_number_integer()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected an integer)");
    return min;
  }
  const long long number = value->get<long long>();
  if (number < min || number > max) {
    problems_.Add(PointerTo(key), "is " + std::to_string(number) + " (expected " + std::to_string(min) + " to " +
                                      std::to_string(max) + ")");
    return min;
  }
  return number;
}

long long JsonObjectReader::WholeNumber(const char* key, long long min, long long max) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return min;
  if (value->is_number_float()) {
    const double number = value->get<double>();
    if (!(std::isfinite(number) && number == std::floor(number) && number >= double(min) && number <= double(max))) {
      problems_.Add(PointerTo(key), "is " + std::to_string(number) + " (expected an integer from " +
                                        std::to_string(min) + " to " + std::to_string(max) + ")");
      return min;
    }
    return static_cast<long long>(number);
  }
  return Integer(key, min, max);
}

std::string JsonObjectReader::String(const char* key) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return {};
  if (!value->is_string()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected a string)");
    return {};
  }
  return value->get<std::string>();
}

bool JsonObjectReader::Bool(const char* key) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return false;
  if (!value->is_boolean()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected true or false)");
    return false;
  }
  return value->get<bool>();
}

std::vector<double> JsonObjectReader::Numbers(const char* key, size_t expected_size) {
  const Json* value = Lookup(key, true);
  if (value == nullptr) return std::vector<double>(expected_size, 0.0);
  const std::string expected =
      expected_size ? "an array of " + std::to_string(expected_size) + " numbers" : "an array of numbers";
  if (!value->is_array() || (expected_size && value->size() != expected_size)) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) +
                                      (value->is_array() ? " of " + std::to_string(value->size()) : "") +
                                      " (expected " + expected + ")");
    return std::vector<double>(expected_size, 0.0);
  }
  std::vector<double> numbers;
  numbers.reserve(value->size());
  for (size_t i = 0; i < value->size(); ++i) {
    const Json& item = (*value)[i];
    if (!item.is_number() || !std::isfinite(item.get<double>())) {
      problems_.Add(PointerTo(key) + "/" + std::to_string(i),
                    std::string("is ") + TypeName(item) + " (expected a finite number)");
      numbers.push_back(0.0);
    } else {
      numbers.push_back(item.get<double>());
    }
  }
  return numbers;
}

std::array<double, 3> JsonObjectReader::Vec3(const char* key) {
  const std::vector<double> v = Numbers(key, 3);
  return {v[0], v[1], v[2]};
}

std::array<double, 16> JsonObjectReader::Matrix4(const char* key) {
  std::array<double, 16> m{};
  const Json* value = Lookup(key, true);
  if (value == nullptr) return m;
  if (!value->is_array() || value->size() != 4) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected 4 rows of 4 numbers)");
    return m;
  }
  for (size_t r = 0; r < 4; ++r) {
    const Json& row = (*value)[r];
    if (!row.is_array() || row.size() != 4) {
      problems_.Add(PointerTo(key) + "/" + std::to_string(r), "is not a row of 4 numbers");
      continue;
    }
    for (size_t c = 0; c < 4; ++c) {
      const Json& item = row[c];
      if (!item.is_number() || !std::isfinite(item.get<double>())) {
        problems_.Add(PointerTo(key) + "/" + std::to_string(r) + "/" + std::to_string(c),
                      std::string("is ") + TypeName(item) + " (expected a finite number)");
      } else {
        m[r * 4 + c] = item.get<double>();
      }
    }
  }
  return m;
}

std::optional<double> JsonObjectReader::OptionalNumber(const char* key) {
  if (!Has(key)) {
    known_.insert(key);
    return std::nullopt;
  }
  return Number(key);
}

std::optional<double> JsonObjectReader::OptionalNumber(const char* key, double min, double max) {
  if (!Has(key)) {
    known_.insert(key);
    return std::nullopt;
  }
  return Number(key, min, max);
}

std::optional<std::string> JsonObjectReader::OptionalString(const char* key) {
  if (!Has(key)) {
    known_.insert(key);
    return std::nullopt;
  }
  return String(key);
}

const Json* JsonObjectReader::Object(const char* key, bool required) {
  const Json* value = Lookup(key, required);
  if (value != nullptr && !value->is_object()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected an object)");
    return nullptr;
  }
  return value;
}

const Json* JsonObjectReader::Array(const char* key, bool required) {
  const Json* value = Lookup(key, required);
  if (value != nullptr && !value->is_array()) {
    problems_.Add(PointerTo(key), std::string("is ") + TypeName(*value) + " (expected an array)");
    return nullptr;
  }
  return value;
}

void JsonObjectReader::Finish() {
  if (object_ == nullptr) return;
  for (auto it = object_->begin(); it != object_->end(); ++it) {
    if (!known_.count(it.key())) problems_.Add(PointerTo(it.key().c_str()), "unknown key (a typo?)");
  }
}

}  // namespace nerfar
