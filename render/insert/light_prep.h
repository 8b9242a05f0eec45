// Internal to render/insert: one object's light made ready for a frame —
// its SG shader, the lobes' unit axes and γ table rows, and every object's
// SSDF query at those axes (the union of the fields shadows).
#pragma once

#include <memory>
#include <vector>

#include "render/insert/inserter.h"
#include "render/insert/object_visibility.h"
#include "render/lighting/incident_light.h"
#include "render/sg/brdf.h"
#include "render/sg/visibility.h"

namespace nerfar {

struct LightPrep {
  std::unique_ptr<SgShader> shader;  // nullptr: not prepared yet
  std::vector<Vec3f> axes;
  std::vector<SgTableRow> gamma_rows;
  std::vector<std::unique_ptr<VisibilityQuery>> queries;  // one per object (nullptr: no field)
  // Near lobes' distances (empty: the light is the same everywhere) and
  // every object's field, to query S along lobes re-aimed at a receiver.
  LightParallax parallax;
  std::vector<const ObjectVisibility*> visibilities;
};

// Prepares `prep` for `light` once (nothing when already prepared), with
// the lobes' distances when `parallax` is given and moves any lobe.
void PrepareLight(const SgMixture& light, const std::vector<InsertObject>& objects, LightPrep& prep,
                  const LightParallax* parallax = nullptr);

}  // namespace nerfar
