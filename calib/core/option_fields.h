// The one `--set key=value` parser: an options struct lists its fields
// (name, kind, address) once, and every command that takes `--set` (nerfar
// train, env, bake, insert, live; NERFAR_BENCH_INSERT_KNOBS) sets them and
// echoes them through these two functions, so parsing, errors and the echo
// are the same everywhere.
//
// Values: kInt and kU64 take whole numbers in the type's range (1e3 is 1000;
// kU64 none below 0), kDouble and kFloat any finite number, kBool true or
// false. The echo is one compact JSON object (keys in alphabetical order); a kFloat
// is written as the shortest decimal that reads back as the same float, so
// `--set step_voxels=0.3` echoes 0.3 (a float widened to double would print
// 0.30000001192092896).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace nerfar {

struct OptionField {
  const char* name;
  enum Kind { kInt, kDouble, kBool, kFloat, kU64 } kind;
  void* ptr;  // an int, double, bool, float or uint64_t as kind says
};

// The field of that name and kind at `value`.
inline OptionField FieldOf(const char* name, int* value) { return {name, OptionField::kInt, value}; }
inline OptionField FieldOf(const char* name, double* value) { return {name, OptionField::kDouble, value}; }
inline OptionField FieldOf(const char* name, bool* value) { return {name, OptionField::kBool, value}; }
inline OptionField FieldOf(const char* name, float* value) { return {name, OptionField::kFloat, value}; }
inline OptionField FieldOf(const char* name, uint64_t* value) { return {name, OptionField::kU64, value}; }

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
