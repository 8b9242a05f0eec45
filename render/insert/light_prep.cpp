#include "render/insert/light_prep.h"

namespace nerfar {

void PrepareLight(const SgMixture& light, const std::vector<InsertObject>& objects, LightPrep& p,
                  const LightParallax* parallax) {
  if (p.shader) return;
  p.shader = std::make_unique<SgShader>(light);
  for (const Sg& lobe : light) {
    p.axes.push_back(Vec3f(Normalized(lobe.axis)));
    p.gamma_rows.push_back(PrepareGamma(lobe.sharpness));
  }
  p.queries.resize(objects.size());
  for (size_t j = 0; j < objects.size(); ++j)
    if (objects[j].visibility && !p.axes.empty()) p.queries[j] = objects[j].visibility->Prepare(p.axes);
  if (parallax && parallax->Active(light)) {
    p.parallax = *parallax;
    for (const InsertObject& o : objects) p.visibilities.push_back(o.visibility);
  }
}

}  // namespace nerfar
