// nerfar bake OBJECT -o object.ssdf: the SSDF visibility field of a virtual
// object (paper §4.3). OBJECT is a mesh (OBJ, PLY, glTF, GLB) or an object
// material JSON (objects/<name>.json) naming its mesh.
#include <cstdio>
#include <filesystem>
#include <string>

#include "app/cli.h"
#include "app/commands.h"
#include "app/object_assets.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/output_guard.h"
#include "calib/core/parallel.h"
#include "calib/object.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

int RunBake(const CommandArgs& args) {
  std::string object, material_path, output, preset = "balanced";
  int grid = -1, dirs = -1, components = -1, bisection = -1;
  std::vector<std::string> sets;
  ArgParser parser("bake", "Bake the SSDF visibility field of a virtual object (its shadows and self-shadows).");
  parser.Positional("OBJECT", &object, "mesh (.obj .ply .gltf .glb) or object JSON naming its mesh");
  parser.Option("-o", &output, "FILE", "the field to write (.ssdf)");
  parser.Required("-o");
  parser.Option("--material", &material_path, "M.json", "material to store with the field (default: OBJECT's own)");
  parser.Option("--preset", &preset, "P", "fast, balanced (default) or accurate; single knobs below override it");
  parser.Option("--grid", &grid, "N", "grid points per axis (balanced: 16)");
  parser.Option("--dirs", &dirs, "R", "octahedral direction map resolution, R x R per point (balanced: 32)");
  parser.Option("--components", &components, "K", "PCA components kept (balanced: 32)");
  parser.Option("--bisection-steps", &bisection, "S", "silhouette refinement rays per crossing (balanced: 6)");
  parser.Option("--set", &sets, "KEY=VALUE",
                "set one option of the list below (repeatable; applied after --preset and the named flags)");
  parser.Epilog("Options (--set KEY=VALUE; the guide's bake table): " + SsdfBakeOptions::Preset("balanced").ToJson() +
                "\n" +
                "presets (measured in docs/BENCHMARKS.md, section ssdf):\n"
                "  fast      grid 16, dirs 24, components 16, bisection 4\n"
                "  balanced  grid 16, dirs 32, components 32, bisection 6\n"
                "  accurate  grid 16, dirs 64, components 64, bisection 8\n"
                "example:\n"
                "  nerfar bake ../shared/scenes/objects/monkey_diffuse.json -o monkey.ssdf --preset fast\n");
  if (!parser.Parse(args)) return 0;

  SsdfBakeOptions options = SsdfBakeOptions::Preset(preset);
  if (grid != -1) options.grid = grid;
  if (dirs != -1) options.dirs = dirs;
  if (components != -1) options.components = components;
  if (bisection != -1) options.bisection_steps = bisection;
  for (const std::string& item : sets) options.Set(item);
  if (const std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    Problems list("nerfar bake");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }

  // OBJECT: a material JSON names its mesh; a mesh may carry its own material.
  const ObjectSource source = ResolveObjectSource(object);
  std::optional<Material> material = source.material;
  std::vector<std::string> inputs = source.inputs;
  if (!material_path.empty()) {
    material = ReadMaterial(material_path);
    inputs.push_back(material_path);
  }
  CheckOutputsSpareInputs({output}, inputs);
  const TriangleMesh mesh = ReadMesh(source.mesh_path);
  if (!material) material = mesh.material;

  LogInfo("bake: " + source.mesh_path + " (" + std::to_string(mesh.TriangleCount()) + " triangles), options " +
          options.ToJson() + ", threads " + std::to_string(ThreadCount()));
  SsdfBakeReport report;
  const SsdfField field = BakeObjectField(mesh, options, material, &report);
  WriteSsdf(output, field);
  const double bytes = static_cast<double>(std::filesystem::file_size(output));
  char line[256];
  std::snprintf(line, sizeof line,
                "bake: wrote %s: %.1f KB (%.2f%% of the %.1f MB raw samples); rays %.1fs, PCA %.1fs, "
                "PCA error rms %.2f° max %.2f°",
                output.c_str(), bytes / 1e3, 100.0 * bytes / report.raw_bytes, report.raw_bytes / 1e6,
                report.seconds_rays, report.seconds_pca, report.pca_rms_rad * 180 / kPi,
                report.pca_max_rad * 180 / kPi);
  LogInfo(line);
  return 0;
}

}  // namespace nerfar
