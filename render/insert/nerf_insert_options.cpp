#include "render/insert/nerf_insert_options.h"

namespace nerfar {

NerfInsertOptions NerfInsertOptions::Preset(const std::string& name, const std::vector<std::string>& sets) {
  NerfInsertOptions o{InsertOptions::Preset(name), NerfSceneOptions::Preset(name)};
  for (const std::string& item : sets) o.Set(item);
  return o;
}

std::vector<OptionField> NerfInsertOptions::Fields() {
  std::vector<OptionField> fields = insert.Fields();
  for (const OptionField& f : nerf.Fields()) fields.push_back(f);
  return fields;
}

void NerfInsertOptions::Set(const std::string& key_value, const std::string& source) {
  SetOptionField(Fields(), key_value, source);
}

std::vector<std::string> NerfInsertOptions::Validate() const {
  std::vector<std::string> problems = insert.Validate();
  for (const std::string& p : nerf.Validate()) problems.push_back(p);
  return problems;
}

}  // namespace nerfar
