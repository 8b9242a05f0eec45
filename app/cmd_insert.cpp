// nerfar insert --nerf scene.nerf --env env.json --object object.ssdf --pose pose.json
//               --dataset DIR --split test -o OUT [--frames DIR] [--background images|nerf] [--preset P]
//               [--set KEY=VALUE]...
// Inserts one or more virtual objects (paper §4.4) into every view of a
// dataset split: OUT/r_XXX.exr composites named like the dataset's images,
// OUT/r_XXX.png tone-mapped, the layers OUT/r_XXX_object.exr, _alpha.exr and
// _kappa.exr, the incident light at the object centre as OUT/probe.exr
// (equirect, scenes/README.md convention), per-stage timings in
// OUT/timings.json and, with --truth, the metrics of DESIGN.md in OUT/report.json.
// With --orbit or --camera-path the views are a camera path's instead, over
// the NeRF's rendering: OUT/frame_NNNN.png and OUT/video.mp4.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/bench.h"
#include "app/camera_path.h"
#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/object_assets.h"
#include "app/video.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/core/metrics.h"
#include "calib/core/parallel.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "render/insert/inserter.h"
#include "render/insert/nerf_insert_options.h"
#include "render/insert/nerf_scene.h"
#include "render/insert/quality.h"
#include "render/insert/ssdf_visibility.h"
#include "render/lighting/env_light.h"
#include "render/lighting/seen_radiance.h"
#include "render/nerf/nerf_file.h"
#include "render/sg/compact_sources.h"
#include "render/sg/fit.h"
#include "render/sg/sphere.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {

struct LoadedObject {
  SsdfField field;
  TriangleMesh mesh;
  ObjectPlacement placement;
  SgMaterial material;
  MaterialMaps maps;
  std::unique_ptr<SsdfVisibility> visibility;
};

// The mesh an .ssdf was baked from: as stored, or relative to the field's folder.
std::string ResolveMesh(const std::string& reference, const std::string& ssdf_path) {
  if (reference.empty()) ThrowInputError(ssdf_path, "names no mesh (give --mesh FILE)");
  const std::string found = FindBeside(reference, ssdf_path);
  if (found.empty()) ThrowInputError(ssdf_path, "its mesh '" + reference + "' was not found (give --mesh FILE)");
  return found;
}

ImageF ReadFrame(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".exr" || ext == ".EXR") return ReadExrRgb(path);
  Image8 image = ReadImage8(path);
  if (image.channels == 1) {
    Image8 rgb(image.width, image.height, 3);
    for (size_t p = 0; p < image.PixelCount(); ++p)
      for (int c = 0; c < 3; ++c) rgb.pixels[p * 3 + c] = image.pixels[p];
    image = rgb;
  }
  return DisplayToLinear(image);
}

ImageF ReadMask(const std::string& path) {
  const Image8 m = ReadImage8(path);
  ImageF out(m.width, m.height, 1);
  for (size_t p = 0; p < m.PixelCount(); ++p) out.pixels[p] = m.pixels[p * m.channels] / 255.0f;
  return out;
}

// "r_003" -> "003" (the index the scenes' ground-truth files use).
std::string IndexSuffix(const std::string& stem) {
  const size_t underscore = stem.rfind('_');
  return underscore == std::string::npos ? stem : stem.substr(underscore + 1);
}

// Grey picture of a ratio image, 0 black to 1 white (above 1 clipped).
Image8 RatioPicture(const ImageF& ratio) {
  Image8 out(ratio.width, ratio.height, 3);
  for (size_t p = 0; p < ratio.pixels.size(); ++p) {
    const float v = std::isfinite(ratio.pixels[p]) ? std::clamp(ratio.pixels[p], 0.0f, 1.0f) : 1.0f;
    for (int c = 0; c < 3; ++c) out.pixels[p * 3 + c] = static_cast<uint8_t>(std::lround(v * 255.0f));
  }
  return out;
}

// One row per view: ours, truth, |ours − truth| × 4 (same exposure), and the
// shadow ratios κ of the metric (ours, truth).
Image8 TruthSheet(const ImageF& ours, const ImageF& ours_without, const ImageF& truth, const ImageF& truth_without,
                  float exposure) {
  ImageF difference(ours.width, ours.height, 3);
  for (size_t i = 0; i < difference.pixels.size(); ++i)
    difference.pixels[i] = 4.0f * std::abs(ours.pixels[i] - truth.pixels[i]);
  return ContactSheet(
      {ToneMapToDisplay(ours, exposure), ToneMapToDisplay(truth, exposure), ToneMapToDisplay(difference, exposure),
       RatioPicture(ShadowRatioImage(ours, ours_without)), RatioPicture(ShadowRatioImage(truth, truth_without))},
      5, ours.width, {"ours", "truth", "|ours - truth| x4", "kappa ours", "kappa truth"});
}

// insert's flags as given: −1, empty or false where a flag was not given
// (the preset's value holds).
struct InsertArgs {
  std::string nerf_path, env_path, dataset_dir, split = "test", output, frames_dir, background = "images";
  std::string preset = "balanced", light_source, truth_dir, light_probe, probe_distances;
  std::vector<std::string> object_paths, pose_paths, mesh_paths, material_paths;
  std::vector<std::string> sets;  // --set KEY=VALUE, in the order given
  int light_directions = -1, sg_lobes = -1, kappa_step = -1, shade_step = -1, occlusion_step = -1;
  int kappa_sample_bins = -1, light_refine_rays = -1;
  double kappa_cache = -1, receiver_reuse = -1, kappa_refine_delta = -1, parallax_min_sharpness = -1;
  double shadow_reach = -1, self_shadow_offset = -1, receiver_min_opacity = -1;
  double seen_group_cm = -1;
  std::string seen_views, seen_agree, normal_probe_voxels;  // set through their fields as given (InsertKnobs)
  bool no_cell_normals = false, no_parallax = false, no_kappa_snap = false, kappa_under_objects = false;
  bool kappa_samples = false, gamma_per_pixel = false, sampled_lobes = false, sg_specular = false;
  bool no_self_shadow = false, no_shadows = false, paper_gamma = false, truth_geometry = false;
  bool light_from_centre = false, no_seen_radiance = false, expected_depth = false, no_support_plane = false;
  bool no_see_through = false, seen_whole_band = false, no_views_cache = false;
  bool specular_parallax = false, no_specular_parallax = false;
  // A video along a camera path instead of the dataset's views.
  bool orbit = false;
  std::string camera_path;
  int orbit_frames = 72, video_width = -1;
  double orbit_radius = -1, orbit_elevation_deg = NAN, fps = -1;  // NaN: not given
  // Derived: ground-truth geometry and a light probe stand in for the NeRF.
  bool without_nerf = false;
  bool video = false;  // --orbit or --camera-path
};

// Every knob of an insert job, each under its `--set` name: the insertion's
// and the NeRF scene's (NerfInsertOptions, as `nerfar live` takes them) and
// whether κ receivers that end on the tag board's plane are taken onto it.
struct InsertKnobs {
  NerfInsertOptions options;
  bool support_plane = true;  // where the dataset has a board.json

  static InsertKnobs Preset(const std::string& name) { return {NerfInsertOptions::Preset(name)}; }
  std::vector<OptionField> Fields() {
    std::vector<OptionField> fields = options.Fields();
    fields.push_back(FieldOf("support_plane", &support_plane));
    return fields;
  }
  // Every knob as one compact JSON object (OUT/options.json).
  std::string ToJson() const {
    InsertKnobs copy = *this;
    return OptionFieldsJson(copy.Fields());
  }
};

// A preset's value as the help shows it.
std::string Shown(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

// The objects, poses, dataset and output flags.
void AddInputFlags(ArgParser& parser, InsertArgs& a) {
  parser.Option(
      "--nerf", &a.nerf_path, "FILE",
      "the scene's HDR NeRF (.nerf; required unless --truth-geometry with --light-probe: then nothing occludes)");
  parser.Option("--env", &a.env_path, "FILE", "environment SGs (env.json from `nerfar env`; default: none)");
  parser.Option("--object", &a.object_paths, "FILE",
                "an object: its SSDF field (.ssdf from `nerfar bake`), or a mesh (.obj .ply .gltf .glb) or object "
                "JSON whose field is baked here; repeatable");
  parser.Required("--object");
  parser.Option("--pose", &a.pose_paths, "FILE", "the object's pose.json (object_to_world); one per --object");
  parser.Option("--mesh", &a.mesh_paths, "FILE",
                "the object's mesh (default: the one the .ssdf or JSON names); per --object");
  parser.Option("--material", &a.material_paths, "FILE",
                "the object's material JSON (default: the .ssdf's); per --object");
  parser.Option("--dataset", &a.dataset_dir, "DIR", "dataset folder with the cameras");
  parser.Required("--dataset");
  parser.Option("--split", &a.split, "NAME", "test (default) or train");
  parser.Option("-o", &a.output, "OUT", "output folder");
  parser.Required("-o");
  parser.Option("--frames", &a.frames_dir, "DIR",
                "camera frames named like the dataset's images (default: those images)");
  parser.Option("--background", &a.background, "B", "images (AR over the camera frames, default) or nerf");
  parser.Option("--preset", &a.preset, "P", "fast, balanced (default) or accurate; the knobs below override it");
  parser.Option("--set", &a.sets, "KEY=VALUE",
                "set one knob of the list at the end, the insertion's or the NeRF scene's (repeatable; applied "
                "after --preset and the named flags, which set the same fields)");
}

// The stages' knobs (light, κ grid and cache, receivers); their help shows the presets' values.
void AddKnobFlags(ArgParser& parser, InsertArgs& a) {
  // The presets' values in the help come from the presets themselves.
  const InsertOptions balanced = InsertOptions::Preset("balanced"), fast = InsertOptions::Preset("fast");
  parser.Option("--light-directions", &a.light_directions, "N",
                "rays from the object centre (balanced: " + Shown(balanced.light.directions) + ")");
  parser.Option("--sg-lobes", &a.sg_lobes, "M",
                "SG lobes of the incident light (balanced: " + Shown(balanced.light.fit.lobes) + ")");
  parser.Option("--kappa-step", &a.kappa_step, "S",
                "κ every S pixels of a 1280-pixel-wide frame (other widths scale it), interpolated between "
                "(balanced: " +
                    Shown(balanced.kappa_step) + ")");
  parser.Option("--shade-step", &a.shade_step, "S",
                "diffuse and self-shadow every S pixels of the object, interpolated where smooth (balanced: " +
                    Shown(balanced.shade_step) + ")");
  parser.Option("--kappa-refine-delta", &a.kappa_refine_delta, "D",
                "coarse κ cells whose corners differ by more than D get every node (balanced: " +
                    Shown(balanced.kappa_refine_delta) + ", fast: " + Shown(fast.kappa_refine_delta) + ")");
  parser.Option("--shadow-reach", &a.shadow_reach, "R",
                "κ within R bounding radii of an object (balanced: " + Shown(balanced.shadow_reach_radii) + ")");
  parser.Option("--self-shadow-offset", &a.self_shadow_offset, "R",
                "self-shadow SSDF queried R bounding radii off the surface (balanced: " +
                    Shown(balanced.self_shadow_offset_radii) + ")");
  parser.Option(
      "--receiver-min-opacity", &a.receiver_min_opacity, "A",
      "κ only on receivers whose NeRF opacity reaches A (balanced: " + Shown(balanced.receiver_min_opacity) + ")");
  parser.Option("--light-source", &a.light_source, "L", "full (default), near (NeRF only) or env (environment only)");
  parser.Option("--occlusion-step", &a.occlusion_step, "S",
                "occlusion first every S pixels, per pixel only where the scene is seen (balanced: " +
                    Shown(balanced.occlusion_step) + "; 1: every pixel)");
  parser.Option("--kappa-cache", &a.kappa_cache, "H",
                "κ kept on a world lattice of H bounding radii while nothing moves (balanced: " +
                    Shown(balanced.kappa_cache_spacing_radii) + "; 0: exact per pixel)");
  parser.Option("--receiver-reuse", &a.receiver_reuse, "T",
                "κ receivers taken from the last frame's within T bounding radii of their planes (balanced: " +
                    Shown(balanced.kappa_reuse_tolerance_radii) + "; 0: every receiver marched)");
}

// κ from samples, parallax, the seen radiance and the NeRF's depth.
void AddLightFlags(ArgParser& parser, InsertArgs& a) {
  const InsertOptions balanced = InsertOptions::Preset("balanced"), fast = InsertOptions::Preset("fast");
  parser.Flag("--kappa-samples", &a.kappa_samples,
              "shadow ratio κ from the light's samples gathered into sources instead of the SG lobes");
  parser.Option("--kappa-sample-bins", &a.kappa_sample_bins, "N",
                "directions the light's samples are gathered into for κ (default: the preset's)");
  parser.Flag("--no-parallax", &a.no_parallax,
              "the light is the same at every shadow receiver, as taken at the object centre (no lobe distances)");
  parser.Option("--light-refine-rays", &a.light_refine_rays, "K",
                "rays averaged over each incident-light direction where the light changes fast (balanced: " +
                    Shown(balanced.light.refine_rays) + "; fast: " + Shown(fast.light.refine_rays) + " = off)");
  parser.Option("--parallax-min-sharpness", &a.parallax_min_sharpness, "L",
                "lobes at least this sharp are re-aimed from each receiver as compact sources (default 10)");
  parser.Flag("--sampled-lobes", &a.sampled_lobes,
              "environment lobes sharper than the light directions resolve go through the directions and the SG fit "
              "like the rest (default: they pass to the incident light analytically)");
  parser.Flag("--light-from-centre", &a.light_from_centre,
              "incident-light rays start at the object centre (the paper), not where they leave the object's mesh");
  parser.Flag("--no-seen-radiance", &a.no_seen_radiance,
              "incident light takes the NeRF's own colour of surfaces seen from below the capture band (default: "
              "the radiance the views from the band agree on nearby)");
  parser.Flag("--no-see-through", &a.no_see_through,
              "incident light keeps the NeRF's semi-transparent content whole (default: only the share that views "
              "from the capture band find matter; the rest lets the environment behind it through)");
  parser.Option("--seen-views", &a.seen_views, "V",
                "views aimed from the capture band at each point a light ray meets from below (default 12)");
  parser.Option("--seen-agree", &a.seen_agree, "F",
                "a point's seen radiance: the mean of its views at least F x as bright as the brightest (default "
                "0.5; 1: the brightest alone)");
  parser.Option("--seen-group-cm", &a.seen_group_cm, "C",
                "light rays whose points lie in one C cm cell share their views (fast: 2, balanced: 1, accurate: "
                "0 = one NeRF voxel)");
  parser.Flag("--expected-depth", &a.expected_depth,
              "NeRF depth (κ receivers, lobe distances) as the opacity-weighted mean, not where transmittance "
              "crosses 1/2");
  parser.Option("--normal-probe-voxels", &a.normal_probe_voxels, "V",
                "NeRF receiver normals from the surface found V voxels to each side (default 3; 0: density "
                "gradient only)");
  parser.Flag("--no-views-cache", &a.no_views_cache,
              "every light takes its own seen-radiance views (default in fast and balanced: the answers of cells "
              "met before are kept, also from the centre rays for the refined sub-rays)");
  parser.Flag("--seen-whole-band", &a.seen_whole_band,
              "seen radiance from views over the whole capture band (default: the views that see the face the "
              "light ray meets, the band only where none does)");
}

// Receivers, self-shadow and specular switches.
void AddShadingFlags(ArgParser& parser, InsertArgs& a) {
  parser.Flag("--no-support-plane", &a.no_support_plane,
              "κ receivers from the NeRF alone (default: where the dataset has a board.json, receivers whose "
              "rays end on the tag board's plane are taken onto it)");
  parser.Flag("--no-kappa-snap", &a.no_kappa_snap, "keep κ in [1 - ε, 1) as computed (default: taken as 1)");
  parser.Flag("--kappa-under-objects", &a.kappa_under_objects,
              "κ also at grid nodes only the objects' pixels cover (default: skipped)");
  parser.Flag("--no-cell-normals", &a.no_cell_normals,
              "a NeRF normal per κ receiver, not one per κ lattice cell shared by all views");
  parser.Flag("--gamma-per-pixel", &a.gamma_per_pixel, "self-shadow γ by an SSDF query per pixel, not per mesh vertex");
  parser.Flag("--no-self-shadow", &a.no_self_shadow, "objects do not shadow themselves or each other");
  parser.Flag("--no-shadows", &a.no_shadows, "no shadows on the scene (κ = 1)");
  parser.Flag("--sg-specular", &a.sg_specular,
              "specular from the SG light (paper eq. 5) instead of the prefiltered incident-light samples");
  parser.Flag("--specular-parallax", &a.specular_parallax,
              "prefiltered reflections looked up from each pixel's point towards where its reflected ray meets the "
              "scene's distance seen from the light centre (the default where the specular is prefiltered: balanced, "
              "accurate)");
  parser.Flag("--no-specular-parallax", &a.no_specular_parallax,
              "prefiltered reflections looked up along the reflected direction, as if all they reflect were distant "
              "(fast's SG specular has no parallax either way)");
  parser.Flag("--paper-gamma", &a.paper_gamma,
              "self-shadow γ = f_h(S)/f_h(π/2) as in the paper (default: horizon-relative)");
}

// A light probe instead of the scene's light, the ground truth, and the epilog.
void AddTruthFlags(ArgParser& parser, InsertArgs& a) {
  parser.Option("--light-probe", &a.light_probe, "FILE",
                "light every object with this panorama fitted with SGs instead");
  parser.Option("--probe-distances", &a.probe_distances, "NERF",
                "with --light-probe: the probe's lobes get their distances (parallax of near light) from this "
                "NeRF's depth seen from the object centre; only the lobe distances come from it");
  parser.Option("--truth", &a.truth_dir, "DIR",
                "ground truth (scenes/*/insert/<object>): writes report.json with object psnr_tm, shadow and "
                "lighting errors, and OUT/<name>_sheet.png (ours, truth, difference, both shadow ratios)");
  parser.Flag("--truth-geometry", &a.truth_geometry,
              "shadow receivers (and, without --nerf, occlusion) from the truth's depth maps instead of the NeRF");
  parser.Epilog(
      "Options (--set KEY=VALUE; light_source takes full, near or env, sg_method block, dense or adam; the guide's "
      "insert knob tables), balanced:\n" +
      InsertKnobs::Preset("balanced").ToJson() +
      "\n"
      "outputs: OUT/<name>.exr and .png, OUT/<name>_object.exr, _alpha.exr, _kappa.exr, OUT/probe.exr\n"
      "(probe_<i>.exr for further objects), OUT/timings.json, OUT/options.json [, OUT/report.json]\n"
      "with --truth also OUT/probe_samples.exr (the light's rays before the SG fit), OUT/probe_opacity.exr\n"
      "(R: the scene's opacity from the centre, G: opacity x hit distance) and the light per region of the sphere\n"
      "with --orbit or --camera-path instead: OUT/frame_NNNN.png (one exposure throughout) and OUT/video.mp4\n"
      "(H.264 by ffmpeg; without ffmpeg the frames stay and the error gives the command to encode them)\n"
      "examples:\n"
      "  nerfar insert --nerf lamps.nerf --object monkey.ssdf --pose "
      "../shared/scenes/lamps/insert/monkey_diffuse/pose.json \\\n"
      "      --dataset ../shared/scenes/lamps -o out/monkey\n"
      "  nerfar insert --nerf lamps.nerf --env env.json --object chair.glb --pose pose.json \\\n"
      "      --dataset ../shared/scenes/lamps -o out/orbit --orbit --video-width 640\n");
}

// A video along an orbit or a nerfstudio camera path.
void AddVideoFlags(ArgParser& parser, InsertArgs& a) {
  parser.Flag("--orbit", &a.orbit,
              "a video orbiting the first object, over the NeRF's rendering: OUT/frame_NNNN.png and OUT/video.mp4 "
              "(ffmpeg); the orbit's radius and elevation are the capture cameras' median ones");
  parser.Option("--orbit-frames", &a.orbit_frames, "N", "frames of one turn (default 72: 3 s at 24 fps)");
  parser.Option("--orbit-radius", &a.orbit_radius, "M", "distance from the object, metres (default: the capture's)");
  parser.Option("--orbit-elevation", &a.orbit_elevation_deg, "DEG",
                "angle above the horizontal, degrees (default: the capture's)");
  parser.Option("--camera-path", &a.camera_path, "FILE",
                "a video along nerfstudio's camera_path.json (its camera_to_world in the dataset's world)");
  parser.Option("--video-width", &a.video_width, "W",
                "video width in pixels, the aspect kept (default: the dataset camera's, or the camera path's)");
  parser.Option("--fps", &a.fps, "F", "video frame rate (default: the camera path's, else 24)");
}

// Every problem with the flags' combination, thrown together.
void CheckUsage(const InsertArgs& a) {
  Problems usage("nerfar insert");
  if (a.nerf_path.empty() && !a.without_nerf) usage.Add("--nerf", "missing (expected the scene's .nerf file)");
  if (a.without_nerf && a.background == "nerf") usage.Add("--background", "nerf needs --nerf");
  if (a.truth_geometry && a.truth_dir.empty()) usage.Add("--truth-geometry", "needs --truth DIR");
  if (!a.probe_distances.empty() && a.light_probe.empty()) usage.Add("--probe-distances", "needs --light-probe FILE");
  if (a.pose_paths.size() != a.object_paths.size())
    usage.Add("--pose", std::to_string(a.pose_paths.size()) + " given for " + std::to_string(a.object_paths.size()) +
                            " objects (expected one per --object)");
  if (!a.mesh_paths.empty() && a.mesh_paths.size() != a.object_paths.size())
    usage.Add("--mesh", "expected none or one per --object");
  if (!a.material_paths.empty() && a.material_paths.size() != a.object_paths.size())
    usage.Add("--material", "expected none or one per --object");
  if (a.background != "images" && a.background != "nerf")
    usage.Add("--background", "'" + a.background + "' (expected images or nerf)");
  if (a.orbit && !a.camera_path.empty()) usage.Add("--orbit", "and --camera-path both given (expected one path)");
  if (a.video && a.without_nerf) usage.Add("--orbit / --camera-path", "need --nerf (it renders the background)");
  if (a.video && !a.frames_dir.empty()) usage.Add("--frames", "has no frames to give a video (the NeRF renders them)");
  if (a.video && !a.truth_dir.empty()) usage.Add("--truth", "has no views of a camera path to compare with");
  if (a.orbit_frames < 1) usage.Add("--orbit-frames", std::to_string(a.orbit_frames) + " (expected at least 1)");
  if (a.video_width != -1 && a.video_width < 2)
    usage.Add("--video-width", std::to_string(a.video_width) + " (expected at least 2 pixels)");
  if (a.fps != -1 && !(a.fps > 0)) usage.Add("--fps", "expected a positive frame rate");
  if (a.orbit_radius != -1 && !(a.orbit_radius > 0)) usage.Add("--orbit-radius", "expected a positive distance");
  if (!std::isnan(a.orbit_elevation_deg) && !(std::abs(a.orbit_elevation_deg) < 90))
    usage.Add("--orbit-elevation", "expected an angle between -90 and 90 degrees");
  usage.ThrowIfAny();
}

// Parses insert's flags into `a`; false when --help was given.
bool ParseInsertArgs(const CommandArgs& args, InsertArgs& a) {
  ArgParser parser("insert", "Insert virtual objects into a captured scene: light, shade, occlude, shadow, composite.");
  AddInputFlags(parser, a);
  AddKnobFlags(parser, a);
  AddLightFlags(parser, a);
  AddShadingFlags(parser, a);
  AddTruthFlags(parser, a);
  AddVideoFlags(parser, a);
  if (!parser.Parse(args)) return false;
  a.without_nerf = a.nerf_path.empty() && a.truth_geometry && !a.light_probe.empty();
  a.video = a.orbit || !a.camera_path.empty();
  CheckUsage(a);
  return true;
}

// The preset's insertion options with the named flags given over them.
InsertOptions InsertOptionsFrom(const InsertArgs& a) {
  InsertOptions options = InsertOptions::Preset(a.preset);
  if (a.light_directions != -1) options.light.directions = a.light_directions;
  if (a.sg_lobes != -1) options.light.fit.lobes = a.sg_lobes;
  if (a.kappa_step != -1) options.kappa_step = a.kappa_step;
  if (a.shade_step != -1) options.shade_step = a.shade_step;
  if (a.kappa_refine_delta != -1) options.kappa_refine_delta = a.kappa_refine_delta;  // validated
  if (a.occlusion_step != -1) options.occlusion_step = a.occlusion_step;
  if (a.kappa_cache >= 0) options.kappa_cache_spacing_radii = a.kappa_cache;
  if (a.receiver_reuse == 0) options.kappa_receiver_reuse = false;
  if (a.receiver_reuse != -1 && a.receiver_reuse != 0)
    options.kappa_reuse_tolerance_radii = a.receiver_reuse;  // validated
  if (a.no_cell_normals) options.receiver_normal_per_cell = false;
  if (a.no_kappa_snap) options.shadow_epsilon_snap = false;
  if (a.kappa_under_objects) options.kappa_skip_covered = false;
  if (a.no_parallax) options.light.parallax = false;
  if (a.kappa_samples) options.kappa_from_samples = true;
  if (a.kappa_sample_bins != -1) options.kappa_sample_bins = a.kappa_sample_bins;  // validated
  if (a.light_from_centre) options.light.start_outside_object = false;
  if (a.sampled_lobes) options.light.analytic_compact_lobes = false;
  if (a.parallax_min_sharpness != -1) options.light.parallax_min_sharpness = a.parallax_min_sharpness;
  if (a.light_refine_rays != -1) options.light.refine_rays = a.light_refine_rays;
  if (a.gamma_per_pixel) options.self_shadow_per_vertex = false;
  if (a.shadow_reach != -1) options.shadow_reach_radii = a.shadow_reach;
  if (a.self_shadow_offset != -1) options.self_shadow_offset_radii = a.self_shadow_offset;
  if (a.receiver_min_opacity != -1) options.receiver_min_opacity = a.receiver_min_opacity;
  if (a.no_self_shadow) options.self_shadow = false;
  if (a.no_shadows) options.shadows = false;
  if (a.paper_gamma) options.self_shadow_horizon = false;
  if (a.sg_specular) options.prefiltered_specular = false;
  if (a.specular_parallax) options.specular_parallax = true;
  if (a.no_specular_parallax) options.specular_parallax = false;
  return options;
}

// The shortest text that reads back as `value` exactly.
std::string ExactText(double value) {
  char text[32];
  return std::string(text, std::to_chars(text, text + sizeof text, value).ptr);
}

// The preset's knobs with the named flags given over them, then --set in
// the order given. The light source's and the NeRF scene's named flags set
// their fields as --set does (the flag named in an error).
InsertKnobs KnobsFrom(const InsertArgs& a) {
  InsertKnobs knobs{{InsertOptionsFrom(a), NerfSceneOptions::Preset(a.preset)}};
  const std::vector<OptionField> fields = knobs.Fields();
  const auto set = [&fields](const std::string& flag, const std::string& key, const std::string& value) {
    SetOptionField(fields, key + "=" + value, flag);
  };
  if (!a.light_source.empty()) set("--light-source", "light_source", a.light_source);
  if (!a.seen_views.empty()) set("--seen-views", "seen_views", a.seen_views);
  if (a.seen_group_cm != -1) set("--seen-group-cm", "seen_group_m", ExactText(a.seen_group_cm / 100.0));
  if (!a.seen_agree.empty()) set("--seen-agree", "seen_agree_fraction", a.seen_agree);
  if (a.no_seen_radiance) set("--no-seen-radiance", "light_seen_radiance", "false");
  if (a.no_see_through) set("--no-see-through", "seen_see_through", "false");
  if (a.seen_whole_band) set("--seen-whole-band", "seen_face_views", "false");
  if (a.no_views_cache) set("--no-views-cache", "seen_cache_views", "false");
  if (a.expected_depth) set("--expected-depth", "surface_depth", "false");
  if (!a.normal_probe_voxels.empty()) set("--normal-probe-voxels", "normal_probe_voxels", a.normal_probe_voxels);
  if (a.no_support_plane) set("--no-support-plane", "support_plane", "false");
  for (const std::string& item : a.sets) SetOptionField(fields, item);
  return knobs;
}

void ValidateOptions(const NerfInsertOptions& options) {
  Problems p("nerfar insert options");
  for (const std::string& s : options.Validate()) p.Add("", s);
  p.ThrowIfAny();
}

// A light probe fitted with SGs (--light-probe): the lobes, the probe's
// pixels (down to 128 × 64) for the prefiltered specular term and its
// compact sources beside those samples.
struct ProbeLight {
  SgMixture light;
  RadianceSamples samples;
  SgMixture compact;
};

ProbeLight FitProbe(const std::string& path, const InsertOptions& options) {
  ProbeLight probe;
  const ImageF panorama = ReadExrRgb(path);
  const bool halve = panorama.width % 128 == 0 && panorama.height % 64 == 0 && panorama.width > 128;
  probe.samples = SamplesFromEquirect(panorama, halve ? 128 : panorama.width, halve ? 64 : panorama.height);
  // The SGs are fitted to the same 128 × 64 samples (2.8° pixels: a 5°
  // source spans two); at half that a sun or a strip light narrower than a
  // pixel leaves its width, and so its energy, to the fit's guess.
  // Compact sources (a sun one or two pixels wide) out first, as lobes of
  // their own energy; the fit takes the rest with the lobes they leave.
  const CompactSplit split =
      SplitCompactSources(probe.samples, options.light.fit.lobes / 2, options.light.fit.hdr_floor);
  probe.samples = split.rest;
  probe.compact = split.lobes;
  SgFitOptions fit = options.light.fit;
  fit.lobes -= static_cast<int>(probe.compact.size());
  probe.light = FitSg(probe.samples, fit);
  probe.light.insert(probe.light.end(), probe.compact.begin(), probe.compact.end());
  std::string compact_list;
  for (const Sg& lobe : probe.compact)
    compact_list += " (λ " + std::to_string(static_cast<int>(lobe.sharpness)) + ", " +
                    std::to_string(LuminanceOf(Integral(lobe))).substr(0, 6) + " Y·sr)";
  LogInfo("insert: lighting every object with " + path + " as " + std::to_string(probe.compact.size()) +
          " compact sources" + compact_list + " and " + std::to_string(fit.lobes) + " fitted SGs");
  return probe;
}

// An .ssdf and the mesh it names (or --mesh), as `nerfar bake` wrote them.
void LoadBakedObject(const InsertArgs& a, size_t i, LoadedObject& o) {
  o.field = ReadSsdf(a.object_paths[i]);
  const std::string mesh_path =
      a.mesh_paths.empty() ? ResolveMesh(o.field.mesh_reference, a.object_paths[i]) : a.mesh_paths[i];
  o.mesh = ReadMesh(mesh_path);
}

// A mesh or an object JSON: its field baked here with the preset's bake
// options (a second or so for a few thousand triangles, a few seconds for a
// million: less than inserting it into one view).
void BakeObject(const InsertArgs& a, size_t i, LoadedObject& o) {
  const ObjectSource source = ResolveObjectSource(a.object_paths[i]);
  o.mesh = ReadMesh(a.mesh_paths.empty() ? source.mesh_path : a.mesh_paths[i]);
  LogInfo("insert: baking the field of " + a.object_paths[i] + " (" + std::to_string(o.mesh.TriangleCount()) +
          " triangles) in memory; `nerfar bake` keeps it for the next run");
  o.field =
      BakeObjectField(o.mesh, SsdfBakeOptions::Preset(a.preset), source.material ? source.material : o.mesh.material);
}

std::vector<LoadedObject> LoadObjects(const InsertArgs& a) {
  std::vector<LoadedObject> loaded(a.object_paths.size());
  for (size_t i = 0; i < a.object_paths.size(); ++i) {
    LoadedObject& o = loaded[i];
    if (fs::path(a.object_paths[i]).extension() == ".ssdf")
      LoadBakedObject(a, i, o);
    else
      BakeObject(a, i, o);
    o.placement = ReadObjectPlacement(a.pose_paths[i]);
    std::optional<Material> material = o.field.material;
    if (!a.material_paths.empty()) material = ReadMaterial(a.material_paths[i]);
    if (!material) material = o.mesh.material;
    if (material) {
      o.material.base_color = material->albedo;
      o.material.roughness = material->roughness;
      o.material.metallic = material->metallic;
      o.maps = LoadMaterialMaps(*material, a.object_paths[i]);
    } else {
      LogWarning("insert: " + a.object_paths[i] + " carries no material; using the default grey");
    }
    o.visibility = std::make_unique<SsdfVisibility>(o.field, o.placement.T_world_object, o.placement.scale);
  }
  return loaded;
}

// The world point an object's incident light is taken at (the inserter's rule).
Vec3 ObjectCentre(const LoadedObject& object) {
  const ObjectPlacement& placement = object.placement;
  return placement.center_world.value_or(placement.T_world_object *
                                         (ComputeBoundingSphere(object.mesh).center * placement.scale));
}

// The probe's lobe distances per object (--probe-distances), from a NeRF's
// depth seen from the object's centre; left empty without one.
struct ProbeDistances {
  std::vector<std::vector<double>> lobes;
  std::vector<DistanceMap> reflections;  // the same depth per direction
};

ProbeDistances ProbeDistancesFrom(const std::string& nerf_path, const SgMixture& probe_light,
                                  const std::vector<LoadedObject>& loaded, const InsertOptions& options,
                                  const NerfSceneOptions& nerf_options) {
  ProbeDistances distances;
  distances.lobes.resize(loaded.size());
  distances.reflections.resize(loaded.size());
  if (nerf_path.empty() || !options.light.parallax) return distances;
  const NerfField distance_nerf = LoadNerf(nerf_path);
  const NerfScene distance_scene(distance_nerf, nerf_options);
  const std::vector<Vec3> dirs = FibonacciSphere(options.light.directions);
  for (size_t i = 0; i < loaded.size(); ++i) {
    std::vector<float> opacity, depth;
    const ObjectPlacement& placement = loaded[i].placement;
    const Vec3 center = ObjectCentre(loaded[i]);
    // As the inserter does: the rays start where they leave the object.
    std::vector<float> starts;
    if (options.light.start_outside_object)
      starts = ObjectExitDistances({&loaded[i].mesh, placement.T_world_object, placement.scale}, center, dirs);
    SampleIncidentLight(distance_scene, {}, center, dirs, LightSource::kNearFieldOnly, &opacity, &depth,
                        starts.empty() ? nullptr : &starts);
    // Distances from opacity alone, without the share of the light the
    // NeRF's radiance explains: the probe is measured apart from the NeRF,
    // so their ratio would mix the NeRF's radiance error (an emitter's peak
    // under-fitted) into where the light comes from, and push near lamps
    // out by that factor.
    distances.lobes[i] = LobeDistances(probe_light, dirs, opacity, depth);
    distances.reflections[i] = ReflectionDistances(dirs, opacity, depth);
    std::string list;
    for (size_t k = 0; k < probe_light.size(); ++k)
      if (std::isfinite(distances.lobes[i][k]))
        list += " λ " + std::to_string(int(probe_light[k].sharpness)) + ": " +
                std::to_string(distances.lobes[i][k]).substr(0, 5) + " m;";
    LogVerbose("insert: object " + std::to_string(i) + " probe lobe distances:" + list);
  }
  return distances;
}

// The inserter's view of the loaded objects (loans from `loaded`, `probe`
// and `distances`, which outlive it).
std::vector<InsertObject> InsertObjects(const std::vector<LoadedObject>& loaded, const ProbeLight* probe,
                                        const ProbeDistances& distances) {
  std::vector<InsertObject> objects(loaded.size());
  for (size_t i = 0; i < loaded.size(); ++i) {
    InsertObject& o = objects[i];
    o.mesh = &loaded[i].mesh;
    o.T_world_object = loaded[i].placement.T_world_object;
    o.scale = loaded[i].placement.scale;
    o.material = loaded[i].material;
    o.visibility = loaded[i].visibility.get();
    const MaterialMaps& maps = loaded[i].maps;
    if (maps.albedo) o.albedo_map = &*maps.albedo;
    if (maps.roughness) o.roughness_map = &*maps.roughness;
    if (maps.metallic) o.metallic_map = &*maps.metallic;
    o.light_center = loaded[i].placement.center_world;
    if (probe != nullptr)
      o.light_override = &probe->light, o.light_samples = &probe->samples, o.light_compact = &probe->compact;
    if (!distances.lobes[i].empty()) o.light_distances = &distances.lobes[i];
    if (!distances.reflections[i].empty()) o.light_sample_distances = &distances.reflections[i];
  }
  return objects;
}

// What the views add up for timings.json and report.json.
struct ViewTotals {
  Json views = Json::array();
  std::vector<double> psnrs, shadow_errors;
  // Object psnr over all views' mask pixels together: a view where the object
  // is nearly hidden (a few pixels at 50-60 dB) weighs by its pixels, not 1/N.
  std::vector<double> view_psnrs;
  std::vector<size_t> view_mask_pixels;
  std::vector<std::vector<double>> stage_ms = std::vector<std::vector<double>>(8);
};

// One view's metrics against the ground truth in `truth_dir` into `view`
// and `totals`, and its sheet; NaN where the truth's size differs.
void TruthMetrics(const std::string& truth_dir, const std::string& stem, const fs::path& out, const ImageF& frame,
                  const ImageF& without, Json& view, ViewTotals& totals, double& psnr, double& shadow) {
  const std::string index = IndexSuffix(stem);
  const fs::path truth(truth_dir);
  const ImageF truth_with = ReadExrRgb((truth / ("rgb_" + index + ".exr")).string());
  const ImageF truth_without = ReadExrRgb((truth.parent_path() / ("bg_" + index + ".exr")).string());
  const ImageF mask = ReadMask((truth / ("mask_" + index + ".png")).string());
  if (truth_with.width != frame.width || truth_with.height != frame.height) {
    LogWarning("insert: " + stem + ": truth size differs from the frame; no metrics");
    return;
  }
  psnr = ObjectPsnrTm(frame, truth_with, mask);
  const ShadowError se = ComputeShadowError(frame, without, truth_with, truth_without, mask);
  shadow = se.error;
  view["object_psnr_tm_db"] = std::isfinite(psnr) ? Json(psnr) : Json(nullptr);
  view["shadow_error"] = std::isfinite(shadow) ? Json(shadow) : Json(nullptr);
  view["shadow_region_pixels"] = se.region;
  view["mean_kappa"] = se.mean_kappa;
  view["mean_kappa_truth"] = se.mean_kappa_gt;
  view["worst_shadow_pixel"] = {{"x", se.worst_x},
                                {"y", se.worst_y},
                                {"kappa", se.worst_kappa},
                                {"kappa_truth", se.worst_kappa_gt},
                                {"background", se.worst_background}};
  WriteImage8((out / (stem + "_sheet.png")).string(),
              TruthSheet(frame, without, truth_with, truth_without, ExposureForPercentile(truth_without)));
  size_t mask_pixels = 0;
  for (size_t p = 0; p < mask.PixelCount(); ++p) mask_pixels += mask.pixels[p * mask.channels] > 0.5f;
  view["object_mask_pixels"] = mask_pixels;
  totals.view_psnrs.push_back(psnr);
  totals.view_mask_pixels.push_back(mask_pixels);
  if (std::isfinite(psnr)) totals.psnrs.push_back(psnr);
  if (std::isfinite(shadow)) totals.shadow_errors.push_back(shadow);
}

// What every view needs besides its frame.
struct ViewJob {
  const InsertArgs& a;
  const Dataset& dataset;
  const std::vector<InsertObject>& objects;
  Inserter& inserter;
  bool nerf_background;  // --background nerf: the NeRF's rendering, else the camera frames
  // A video's frames: the tone-mapped composite alone, at the first frame's
  // exposure throughout (a per-frame exposure would flicker); nullptr: the
  // composite, its PNG and the layers per view.
  float* video_exposure = nullptr;
};

// A view's composite, its PNG and its layers (object, alpha, κ).
void WriteViewLayers(const fs::path& out, const std::string& stem, const CameraIntrinsics& camera, const ImageF& frame,
                     const ImageF& without, const InsertLayers& layers) {
  WriteExrRgb((out / (stem + ".exr")).string(), frame);
  WriteImage8((out / (stem + ".png")).string(), ToneMapToDisplay(frame, ExposureForPercentile(without)));
  WriteExrRgb((out / (stem + "_object.exr")).string(),
              ExpandLayer(layers.object, layers.gbuffer.rect, camera.width, camera.height, 0.0f));
  WriteExr((out / (stem + "_alpha.exr")).string(),
           ExpandLayer(layers.alpha, layers.gbuffer.rect, camera.width, camera.height, 0.0f), {"Y"});
  WriteExr((out / (stem + "_kappa.exr")).string(),
           ExpandLayer(layers.kappa, layers.kappa_rect, camera.width, camera.height, 1.0f), {"Y"});
}

// One view: its background, the insertion, the composite and layers
// written, its timings and metrics into `totals` and one table row.
void InsertView(const ViewJob& job, const DatasetFrame& frame_info, ViewTotals& totals) {
  const InsertArgs& a = job.a;
  const fs::path image_path(frame_info.image_path);
  const std::string stem = image_path.stem().string();
  CameraIntrinsics camera = job.dataset.CameraOf(frame_info);
  ImageF frame;
  double background_ms = 0;
  if (job.nerf_background) {
    const double t0 = NowSeconds();
    frame = job.inserter.RenderBackground(camera, frame_info.T_world_camera);
    background_ms = (NowSeconds() - t0) * 1e3;
  } else {
    const std::string path =
        a.frames_dir.empty() ? frame_info.image_path : (fs::path(a.frames_dir) / image_path.filename()).string();
    frame = ReadFrame(path);
    if (frame.width != camera.width || frame.height != camera.height) camera = camera.Scaled(frame.width, frame.height);
  }
  const ImageF without = frame;
  InsertLayers layers;
  ImageF receiver_distance, receiver_normal;
  ReceiverOverride receivers;
  if (a.truth_geometry) {
    const fs::path depth_path = fs::path(a.truth_dir) / ("depth_" + IndexSuffix(stem) + ".exr");
    const ImageF depth = ReadExrChannel(depth_path.string());
    if (depth.width != camera.width || depth.height != camera.height)
      ThrowInputError(depth_path.string(), "size differs from the frame (expected " + std::to_string(camera.width) +
                                               "x" + std::to_string(camera.height) + ")");
    ReceiversFromDepth(depth, camera, frame_info.T_world_camera, receiver_distance, receiver_normal);
    receivers = {&receiver_distance, &receiver_normal, a.without_nerf};
  }
  const InsertTimings t =
      job.inserter.Render(camera, frame_info.T_world_camera, job.objects, frame, &layers, receivers);
  const fs::path out(a.output);
  if (job.video_exposure == nullptr) {
    WriteViewLayers(out, stem, camera, frame, without, layers);
  } else {
    if (*job.video_exposure <= 0) *job.video_exposure = ExposureForPercentile(without);
    WriteImage8((out / (stem + ".png")).string(), ToneMapToDisplay(frame, *job.video_exposure));
  }
  Json view = {{"name", stem},
               {"light_ms", t.light_ms},
               {"fit_ms", t.fit_ms},
               {"raster_ms", t.raster_ms},
               {"shade_ms", t.shade_ms},
               {"occlusion_ms", t.occlusion_ms},
               {"kappa_ms", t.kappa_ms},
               {"total_ms", t.total_ms},
               {"background_ms", background_ms},
               {"lights_recomputed", t.lights_recomputed},
               {"object_pixels", layers.gbuffer.covered},
               {"kappa_queries", layers.kappa_queries}};
  const double values[8] = {t.light_ms,     t.fit_ms,   t.raster_ms, t.shade_ms,
                            t.occlusion_ms, t.kappa_ms, t.total_ms,  background_ms};
  for (int s = 0; s < 8; ++s) totals.stage_ms[s].push_back(values[s]);
  double psnr = NAN, shadow = NAN;
  if (!a.truth_dir.empty()) TruthMetrics(a.truth_dir, stem, out, frame, without, view, totals, psnr, shadow);
  std::printf("%-8s %9.2f %7.2f %8.2f %8.2f %8.2f %9.2f %8.2f %9.1f %10.2f %8.3f\n", stem.c_str(), t.light_ms, t.fit_ms,
              t.raster_ms, t.shade_ms, t.occlusion_ms, t.kappa_ms, t.total_ms, background_ms, psnr, shadow);
  totals.views.push_back(view);
}

// Where the first object's light differs from the truth's probe: the raw
// samples (before the SG fit, with the analytic lobes) as
// OUT/probe_samples.exr and their lighting error, the scene's opacity seen
// from the centre as OUT/probe_opacity.exr, and the luminance flux per
// region of the sphere of the truth, the fit and the samples.
void LightDiagnostics(const Inserter& inserter, const fs::path& true_probe, const std::string& output, Json& report) {
  const ImageF truth_probe = ReadExrRgb(true_probe.string());
  const ImageF fitted = RenderEquirect(inserter.Light(0), truth_probe.width, truth_probe.height);
  ImageF raw, opacity, opacity_depth;
  const ImageF ones(truth_probe.width, truth_probe.height, 3, 1.0f);
  if (inserter.LightCache(0).valid() && inserter.LightCache(0).samples().size() > 0) {
    raw = SamplesPanorama(inserter.LightCache(0).samples(), truth_probe.width, truth_probe.height);
    // The compact lobes that passed analytically, beside the samples.
    const ImageF compact = RenderEquirect(inserter.LightCache(0).compact(), truth_probe.width, truth_probe.height);
    for (size_t k = 0; k < raw.pixels.size(); ++k) raw.pixels[k] += compact.pixels[k];
    WriteExrRgb((fs::path(output) / "probe_samples.exr").string(), raw, ExrPixelType::kFloat);
    report["lighting_error_samples"] = LightingError(raw, truth_probe);
    report["light_refined_directions"] = inserter.LightCache(0).refined();
    std::printf("lighting error of the raw samples (before the SG fit, with the analytic lobes): %.3f\n",
                report["lighting_error_samples"].get<double>());
    // R = opacity Ô (where the NeRF hides the environment), G = Ô × hit
    // distance (m), B = 0.
    const IncidentLight& cache = inserter.LightCache(0);
    RadianceSamples o = cache.samples(), od = cache.samples();
    for (size_t k = 0; k < o.size() && k < cache.opacity().size() && k < cache.depth().size(); ++k) {
      o.radiance[k] = Vec3{1.0, 1.0, 1.0} * double(cache.opacity()[k]);
      od.radiance[k] = Vec3{1.0, 1.0, 1.0} * double(cache.opacity()[k]) * double(cache.depth()[k]);
    }
    opacity = SamplesPanorama(o, truth_probe.width, truth_probe.height);
    opacity_depth = SamplesPanorama(od, truth_probe.width, truth_probe.height);
    ImageF layers = opacity;
    for (size_t k = 0; k < layers.PixelCount(); ++k) {
      layers.pixels[3 * k + 1] = opacity_depth.pixels[3 * k];
      layers.pixels[3 * k + 2] = 0.0f;
    }
    WriteExrRgb((fs::path(output) / "probe_opacity.exr").string(), layers, ExrPixelType::kFloat);
  }
  Json regions = Json::array();
  std::printf("light flux per region (Y x sr): %-42s %9s %9s %9s %9s %9s\n", "region", "truth", "fitted", "samples",
              "opacity", "depth_m");
  for (const SphereRegion& region : LightReportRegions(truth_probe)) {
    const double t = RegionFlux(truth_probe, region), f = RegionFlux(fitted, region);
    const double r = raw.empty() ? NAN : RegionFlux(raw, region);
    const double o = opacity.empty() ? NAN : RegionFlux(opacity, region) / RegionFlux(ones, region);
    const double depth = opacity.empty() ? NAN : RegionFlux(opacity_depth, region) / RegionFlux(opacity, region);
    regions.push_back({{"region", region.name},
                       {"truth", t},
                       {"fitted", f},
                       {"samples", raw.empty() ? Json() : Json(r)},
                       {"mean_opacity", opacity.empty() ? Json() : Json(o)},
                       {"mean_depth_m", std::isfinite(depth) ? Json(depth) : Json()}});
    std::printf("light flux per region (Y x sr): %-42s %9.4f %9.4f %9.4f %9.3f %9.3f\n", region.name.c_str(), t, f, r,
                o, depth);
  }
  report["light_flux_per_region"] = regions;
}

// OUT/report.json (--truth): the views' metrics, their means and medians,
// and the light's error against the truth's probe.
void WriteReport(const InsertArgs& a, const InsertOptions& options, const Inserter& inserter,
                 const ViewTotals& totals) {
  Json report = {
      {"truth", a.truth_dir}, {"views", totals.views}, {"light_source", LightSourceName(options.light.source)}};
  const auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? NAN : s / v.size();
  };
  const std::vector<double>& psnrs = totals.psnrs;
  const std::vector<double>& shadow_errors = totals.shadow_errors;
  report["mean_object_psnr_tm_db"] = psnrs.empty() ? Json(nullptr) : Json(mean(psnrs));
  report["mean_shadow_error"] = shadow_errors.empty() ? Json(nullptr) : Json(mean(shadow_errors));
  const double pooled_psnr = PooledPsnr(totals.view_psnrs, totals.view_mask_pixels);
  const double median_shadow = shadow_errors.empty() ? NAN : MedianOf(shadow_errors);
  report["pooled_object_psnr_tm_db"] = std::isfinite(pooled_psnr) ? Json(pooled_psnr) : Json(nullptr);
  // The ratio κ = with / without over a black camera pixel makes one view's
  // error unbounded where a few object pixels land on it; the median is
  // what most views show.
  report["median_shadow_error"] = std::isfinite(median_shadow) ? Json(median_shadow) : Json(nullptr);
  const fs::path true_probe = fs::path(a.truth_dir) / "probe.exr";
  std::error_code error;
  if (fs::is_regular_file(true_probe, error)) {
    const double lighting = LightingError(inserter.Light(0), ReadExrRgb(true_probe.string()));
    report["lighting_error"] = lighting;
    std::printf("lighting error (relative RMS irradiance, 64 normals): %.3f\n", lighting);
    LightDiagnostics(inserter, true_probe, a.output, report);
  }
  std::printf("object psnr_tm mean %.2f dB, pooled %.2f dB; shadow error mean %.3f, median %.3f\n", mean(psnrs),
              pooled_psnr, mean(shadow_errors), median_shadow);
  WriteJsonFile((fs::path(a.output) / "report.json").string(), report);
}

// OUT/probe.exr (probe_<i>.exr for further objects): the incident light at
// each object's centre, as the scenes' probes are stored; OUT/timings.json.
void WriteProbesAndTimings(const InsertArgs& a, const Inserter& inserter, size_t n_objects, const ViewTotals& totals) {
  for (size_t i = 0; i < n_objects; ++i) {
    const std::string name = i == 0 ? "probe.exr" : "probe_" + std::to_string(i) + ".exr";
    WriteExrRgb((fs::path(a.output) / name).string(), RenderEquirect(inserter.Light(i), 256, 128),
                ExrPixelType::kFloat);
  }
  const char* stage_names[8] = {"light_ms",     "fit_ms",   "raster_ms", "shade_ms",
                                "occlusion_ms", "kappa_ms", "total_ms",  "background_ms"};
  Json medians = Json::object();
  for (int s = 0; s < 8; ++s) medians[stage_names[s]] = MedianOf(totals.stage_ms[s]);
  WriteJsonFile((fs::path(a.output) / "timings.json").string(),
                {{"threads", ThreadCount()},
                 {"note", "per-stage wall time of each frame; the first frame includes the cold SG fit"},
                 {"median", medians},
                 {"views", totals.views}});
}

// The views of --orbit (around `centre`, by default as the capture's cameras
// see it) or --camera-path as a dataset of frames named frame_NNNN, each
// with its own camera.
Dataset VideoViews(const InsertArgs& a, const Dataset& capture, const CameraPath& from_file, const Vec3& centre) {
  CameraPath path = from_file;
  if (a.orbit) {
    std::vector<Pose> capture_poses;
    for (const DatasetFrame& frame : capture.frames) capture_poses.push_back(frame.T_world_camera);
    Orbit orbit = OrbitOfCapture(capture_poses, centre, a.orbit_frames);
    if (a.orbit_radius != -1) orbit.radius_m = a.orbit_radius;
    if (!std::isnan(a.orbit_elevation_deg)) orbit.elevation_rad = a.orbit_elevation_deg * kPi / 180.0;
    for (const Pose& pose : OrbitPoses(orbit)) path.views.push_back({capture.camera, pose});
    LogInfo("insert: orbit of " + std::to_string(orbit.frames) + " frames around (" + Shown(centre.x) + ", " +
            Shown(centre.y) + ", " + Shown(centre.z) + ") at " + Shown(orbit.radius_m) + " m, " +
            Shown(orbit.elevation_rad * 180.0 / kPi) + " degrees up");
  }
  Dataset views;
  views.dir = a.output;
  views.per_frame_cameras = true;
  for (size_t i = 0; i < path.views.size(); ++i) {
    DatasetFrame frame;
    frame.image_path = (fs::path(a.output) / VideoFrameName(i)).string() + ".png";
    frame.T_world_camera = path.views[i].T_world_camera;
    const CameraIntrinsics& camera = path.views[i].camera;
    frame.camera = VideoCamera(camera, a.video_width != -1 ? a.video_width : camera.width);
    views.frames.push_back(frame);
  }
  views.camera = views.frames.front().camera;
  return views;
}

// OUT/video.mp4 from the frames written, at the path's or --fps's rate.
void WriteVideo(const InsertArgs& a, const Dataset& views, double path_fps) {
  const double fps = a.fps != -1 ? a.fps : path_fps;
  const std::string video = (fs::path(a.output) / "video.mp4").string();
  EncodeMp4((fs::path(a.output) / VideoFramePattern()).string(), fps, video);
  LogInfo("insert: wrote " + video + " (" + std::to_string(views.camera.width) + "x" +
          std::to_string(views.camera.height) + ", " + std::to_string(views.frames.size()) + " frames at " +
          Shown(fps) + " fps)");
}

// How the light's seen radiance is taken, for the log.
std::string SeenRadianceNote(const NerfSceneOptions& o, const NerfField& field) {
  return o.light_seen_radiance ? "on (" + SeenViewsNote(field, o.seen) + ")" : "off";
}

}  // namespace

int RunInsert(const CommandArgs& args) {
  InsertArgs a;
  if (!ParseInsertArgs(args, a)) return 0;
  const InsertKnobs knobs = KnobsFrom(a);
  const InsertOptions& options = knobs.options.insert;
  const NerfSceneOptions& nerf_options = knobs.options.nerf;
  ValidateOptions(knobs.options);

  // Inputs.
  const Dataset capture = ReadDataset(DatasetSplitPath(a.dataset_dir, a.split));
  const CameraPath path_file = a.camera_path.empty() ? CameraPath{} : ReadCameraPath(a.camera_path);
  const size_t path_views = a.orbit ? static_cast<size_t>(a.orbit_frames) : path_file.views.size();
  CheckOutputsSpareInputs(a.video ? VideoOutputs(a.output, path_views, a.object_paths.size())
                                  : InsertOutputs(a.output, capture, a.object_paths.size()),
                          Paths(a.nerf_path, a.env_path, a.light_probe, a.probe_distances, a.frames_dir,
                                DatasetInputs(capture), a.object_paths, a.pose_paths, a.mesh_paths, a.material_paths,
                                InsertTruthInputs(a.truth_dir), a.camera_path));
  if (a.video && !FindOnPath("ffmpeg"))
    LogWarning("insert: ffmpeg not found on PATH (apt-get install ffmpeg): the frames are written, the video not");
  // Without a NeRF (ground-truth inputs) the scene is empty: nothing occludes.
  NerfField nerf = a.without_nerf ? NerfField{} : LoadNerf(a.nerf_path);
  // The field does not change from here on: rays read its compact copy (same samples, quantised values).
  if (!a.without_nerf) nerf.UpdateRenderCopy();
  std::unique_ptr<SceneField> scene_field;
  if (a.without_nerf)
    scene_field = std::make_unique<EmptyScene>(capture.aabb ? *capture.aabb : Aabb{{-1, -1, -1}, {1, 1, 1}});
  else
    scene_field = std::make_unique<NerfScene>(nerf, nerf_options);
  const SceneField& scene = *scene_field;
  EnvLight environment;
  if (!a.env_path.empty()) {
    environment = ReadEnvLight(a.env_path);
    if (DropIfNegligible(environment))
      LogInfo("insert: " + a.env_path + " marks the environment as negligible: it is dropped");
  }
  const std::vector<LoadedObject> loaded = LoadObjects(a);
  const Dataset dataset = a.video ? VideoViews(a, capture, path_file, ObjectCentre(loaded.front())) : capture;
  const ProbeLight probe = a.light_probe.empty() ? ProbeLight{} : FitProbe(a.light_probe, options);
  const ProbeDistances distances = ProbeDistancesFrom(a.probe_distances, probe.light, loaded, options, nerf_options);
  MakeDirectories(a.output);
  const std::string options_json = knobs.ToJson();
  LogInfo("insert: options " + options_json + ", threads " + std::to_string(ThreadCount()) +
          (a.without_nerf ? std::string()
                          : std::string(", nerf depth ") + (nerf_options.surface_depth ? "surface" : "expected") +
                                ", light seen radiance " + SeenRadianceNote(nerf_options, nerf) + ", normal probe " +
                                std::to_string(nerf_options.normal_probe_voxels) + " voxels"));
  WriteFileAtomic((fs::path(a.output) / "options.json").string(), options_json + "\n");
  const std::vector<InsertObject> objects = InsertObjects(loaded, a.light_probe.empty() ? nullptr : &probe, distances);

  Inserter inserter(scene, environment.lobes, options, environment.distance_m);
  const fs::path board_path = fs::path(a.dataset_dir) / "board.json";
  if (knobs.support_plane && !a.truth_geometry && fs::exists(board_path) && !dataset.frames.empty()) {
    const SupportPlane plane =
        PlaneOfBoard(ReadBoard(board_path.string()), dataset.frames.front().T_world_camera.translation);
    inserter.set_support_plane(plane);
    LogInfo("insert: shadow receivers that end on the board's plane (" + board_path.string() + ") are taken onto it");
  }
  ViewTotals totals;
  std::printf("%-8s %9s %7s %8s %8s %8s %9s %8s %9s %10s %8s\n", "view", "light_ms", "fit_ms", "raster", "shade",
              "occlude", "kappa_ms", "total", "bg_ms", "psnr_obj", "shadow");
  float video_exposure = 0;
  const ViewJob job{
      a, dataset, objects, inserter, a.video || a.background == "nerf", a.video ? &video_exposure : nullptr};
  Progress progress("insert", dataset.frames.size());
  for (size_t i = 0; i < dataset.frames.size(); ++i) {
    InsertView(job, dataset.frames[i], totals);
    progress.Update(i + 1);
  }
  progress.Finish();
  WriteProbesAndTimings(a, inserter, objects.size(), totals);
  if (a.video) WriteVideo(a, dataset, path_file.views.empty() ? 24.0 : path_file.fps);
  if (!a.truth_dir.empty()) WriteReport(a, options, inserter, totals);
  LogInfo("insert: wrote " + std::to_string(dataset.frames.size()) + " views to " + a.output);
  return 0;
}

}  // namespace nerfar
