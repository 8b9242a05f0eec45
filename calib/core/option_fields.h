// The one `--set key=value` parser: an options struct lists its fields
// (name, kind, address) once, and every command that takes `--set` (nerfar
// train, env, bake, insert, live; NERFAR_BENCH_INSERT_KNOBS) sets them and
// echoes them through these two functions, so parsing, errors and the echo
// are the same everywhere.
//
// Values: kInt and kU64 take whole numbers in the type's range (1e3 is 1000;
// kU64 none below 0), kDouble and kFloat any finite number, kBool true or
// false, kChoice one of its names (an enum's values by name; any other name
// is refused naming the allowed ones, and the echo writes the name). The echo is one compact JSON object (keys in
// alphabetical order); a kFloat is written as the shortest decimal that reads back as the same float, so
// `--set step_voxels=0.3` echoes 0.3 (a float widened to double would print
// 0.30000001192092896).
#pragma once

#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace nerfar {

struct OptionField {
  const char* name;
  enum Kind { kInt, kDouble, kBool, kFloat, kU64, kChoice } kind;
  void* ptr;  // an int, double, bool, float, uint64_t or (kChoice) enum as kind says
  // kChoice: the names of the enum's values 0, 1, 2, ... in order, and how
  // the enum at ptr is read and written as that index.
  std::vector<const char*> choices = {};
  int (*get_choice)(const void* ptr) = nullptr;
  void (*set_choice)(void* ptr, int index) = nullptr;
};

// The field of that name and kind at `value`.
inline OptionField FieldOf(const char* name, int* value) { return {name, OptionField::kInt, value}; }
inline OptionField FieldOf(const char* name, double* value) { return {name, OptionField::kDouble, value}; }
inline OptionField FieldOf(const char* name, bool* value) { return {name, OptionField::kBool, value}; }
inline OptionField FieldOf(const char* name, float* value) { return {name, OptionField::kFloat, value}; }
inline OptionField FieldOf(const char* name, uint64_t* value) { return {name, OptionField::kU64, value}; }
// A named choice: `names` are those of the enum's values 0, 1, 2, ... in order.
template <typename Enum>
requires std::is_enum_v<Enum> OptionField FieldOf(const char* name, Enum* value, std::vector<const char*> names) {
  return {name,
          OptionField::kChoice,
          value,
          std::move(names),
          [](const void* p) { return static_cast<int>(*static_cast<const Enum*>(p)); },
          [](void* p, int index) { *static_cast<Enum*>(p) = static_cast<Enum>(index); }};
}

// Sets the field "key=value" names. Throws InputError "SOURCE key=value: ..."
// (SOURCE: the flag or variable the text came from) when there is no '=',
// when no field has that key (the known keys listed), or when the value is
// not of the field's kind (naming key, value and kind); the field is left as
// it was then.
void SetOptionField(const std::vector<OptionField>& fields, const std::string& key_value,
                    const std::string& source = "--set");

// The fields as one compact JSON object, e.g. {"steps":3000,"lr":0.1,"smooth":true}.
std::string OptionFieldsJson(const std::vector<OptionField>& fields);

}  // namespace nerfar
