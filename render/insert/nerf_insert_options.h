// The knobs of an insertion into a NeRF scene, one preset for both halves:
// the insertion's (InsertOptions) and the NeRF scene's (NerfSceneOptions),
// each under its `--set` name. `nerfar insert` and `nerfar live` read their
// `--set KEY=VALUE` items through this one list, so a key means the same in
// both and a key of neither is refused.
#pragma once

#include <string>
#include <vector>

#include "calib/core/option_fields.h"
#include "render/insert/insert_options.h"
#include "render/insert/nerf_scene.h"

namespace nerfar {

struct NerfInsertOptions {
  InsertOptions insert;
  NerfSceneOptions nerf;

  // Both halves' preset `name` (fast, balanced, accurate; InputError
  // otherwise) with `sets` ("key=value") over them in the order given
  // (InputError naming an unknown key or a bad value).
  static NerfInsertOptions Preset(const std::string& name, const std::vector<std::string>& sets = {});
  // The insertion's fields, then the NeRF scene's.
  std::vector<OptionField> Fields();
  // One field from "key=value"; `source` names where it came from in errors.
  void Set(const std::string& key_value, const std::string& source = "--set");
  // Every problem of both halves, "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
};

}  // namespace nerfar
