#!/usr/bin/env bash
# The offline pipeline end to end on a built-in synthetic scene, headless:
# synth (a small 'window' scene with ground truth) -> train (fast NeRF) ->
# render (test views, psnr_tm) -> env (environment SGs) -> bake (the torus's
# SSDF) -> insert (the torus into the test views, scored against the truth).
# Usage: scripts/demo.sh [OUT_DIR] (default demo_out). Sets up the machine first.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-demo_out}
nerfar=build/app/nerfar
mkdir -p "$out"
echo "== 1/6 synth: a tabletop with a hidden window light and ground truth for insertion"
$nerfar synth --scene window -o "$out/scene" --res 200x150 --views 60 --test-views 4 --preset fast
echo "== 2/6 train: HDR NeRF, fast preset"
$nerfar train "$out/scene" -o "$out/scene.nerf" --preset fast --minutes "${NERFAR_DEMO_MINUTES:-3}"
echo "== 3/6 render: test views and psnr_tm"
$nerfar render "$out/scene.nerf" --dataset "$out/scene" --split test -o "$out/render"
echo "== 4/6 env: the distant light the NeRF does not hold"
$nerfar env "$out/scene.nerf" -o "$out/env.json" --preview "$out/env.exr" --preset fast
echo "== 5/6 bake: the torus's visibility field"
$nerfar bake "$out/scene/objects/torus_diffuse.obj" --material "$out/scene/objects/torus_diffuse.json" \
  -o "$out/torus.ssdf" --preset fast
echo "== 6/6 insert: the torus into the test views"
$nerfar insert --nerf "$out/scene.nerf" --env "$out/env.json" --object "$out/torus.ssdf" \
  --pose "$out/scene/insert/torus_diffuse/pose.json" --dataset "$out/scene" -o "$out/insert" --preset fast \
  --truth "$out/scene/insert/torus_diffuse"
echo "done: composites in $out/insert, NeRF renders in $out/render, contact sheet $out/scene/contact_sheet.png"
