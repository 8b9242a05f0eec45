#!/usr/bin/env bash
# Insertion quality end to end on one scene, ours beside the paper's ablations and its PhySG-like
# baseline, measured as ../shared/eval/e2e.sh measures ours (its metrics.py, the same views and frames).
#
# Usage: scripts/eval_light.sh NERFAR SCENE_DIR OBJECTS_DIR PRESET OUT_DIR [VARIANTS]
#   VARIANTS (comma-separated, default all): ours, near (near field only), env (environment only),
#   physg (environment estimated without the NeRF's light and visibility, used alone).
# OUT_DIR/scene.nerf is trained with PRESET when absent (or link a trained model there first);
# env.json, env_physg.json and the baked objects are reused when present. Prints the environment's
# irradiance error against SCENE_DIR/env.exr, then one line per object and variant:
#   object variant psnr_tm(mean over views) shadow(median over views) shadow(mean) lighting
set -u
exe=$(realpath "$1"); scene=$(realpath "$2"); objs=$(realpath "$3"); preset=$4; out=$5
variants=${6:-ours,near,env,physg}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
eval_dir=${NERFAR_EVAL:-$(realpath "$here/../../shared/eval")}
metrics="$eval_dir/metrics.py"
[ -f "$metrics" ] || { echo "eval_light: $metrics not found (set NERFAR_EVAL to the folder of metrics.py)" >&2; exit 2; }
mkdir -p "$out"
run() { # log-file command...: runs a stage, its output in the log, and says which failed
  local log=$1; shift
  "$@" >"$log" 2>&1 || { echo "eval_light: failed ($(basename "$log")): $*" >&2; return 1; }
}
[ -f "$out/scene.nerf" ] || run "$out/train.log" "$exe" train "$scene" -o "$out/scene.nerf" --preset "$preset" --quiet || exit 1
[ -f "$out/env.json" ] || run "$out/env.log" "$exe" env "$out/scene.nerf" -o "$out/env.json" --preview "$out/env.exr" \
  --preset "$preset" || exit 1
if [[ ",$variants," == *",physg,"* && ! -f "$out/env_physg.json" ]]; then
  run "$out/env_physg.log" "$exe" env "$out/scene.nerf" -o "$out/env_physg.json" --preview "$out/env_physg.exr" \
    --preset "$preset" --set ignore_near_field=true || exit 1
fi
for e in env env_physg; do
  [ -f "$scene/env.exr" ] && [ -f "$out/$e.exr" ] &&
    echo "$e irradiance error (upper): $(/usr/bin/python3 "$metrics" irradiance "$out/$e.exr" "$scene/env.exr" --upper)"
done
mkdir -p "$out/frames"
for f in "$scene"/insert/bg_*.exr; do b=$(basename "$f"); ln -sf "$f" "$out/frames/r_${b#bg_}"; done
for d in "$scene"/insert/*/; do
  obj=$(basename "$d"); [ -f "$objs/$obj.obj" ] || continue
  [ -f "$out/$obj.ssdf" ] || run "$out/bake_$obj.log" "$exe" bake "$objs/$obj.obj" --material "$objs/$obj.json" \
    -o "$out/$obj.ssdf" || continue
  for v in ${variants//,/ }; do
    env_file=$out/env.json source=full
    case $v in
      ours) ;;
      near) source=near ;;
      env) source=env ;;
      physg) env_file=$out/env_physg.json source=env ;;
      *) echo "eval_light: unknown variant $v (expected ours, near, env, physg)" >&2; exit 2 ;;
    esac
    res=$out/res_${obj}_$v
    rm -rf "$res"
    run "$out/insert_${obj}_$v.log" "$exe" insert --nerf "$out/scene.nerf" --env "$env_file" --object "$out/$obj.ssdf" \
      --pose "$d/pose.json" --dataset "$scene" --split test --frames "$out/frames" --preset "$preset" \
      --light-source "$source" -o "$res" || continue
    NERFAR_EVAL=$eval_dir /usr/bin/python3 - "$res" "$scene/insert" "$obj" "$v" <<'PY'
import os, sys
import numpy as np
res, ins, obj, variant = sys.argv[1:5]
sys.path.insert(0, os.environ["NERFAR_EVAL"]); import metrics as M
o, s = [], []
for i in range(8):
    a = os.path.join(res, f"r_{i:03d}.exr")
    if not os.path.exists(a): continue
    ours, rgb, bg = M.read_exr(a), M.read_exr(f"{ins}/{obj}/rgb_{i:03d}.exr"), M.read_exr(f"{ins}/bg_{i:03d}.exr")
    mask = M.read_mask(f"{ins}/{obj}/mask_{i:03d}.png")
    if mask.sum() > 50: o.append(M.psnr_tm(ours, rgb, mask))
    e, n = M.shadow_error(ours, rgb, bg, mask)
    if n > 50: s.append(e)
pr = os.path.join(res, "probe.exr")
le = M.irradiance_error(M.read_exr(pr), M.read_exr(f"{ins}/{obj}/probe.exr")) if os.path.exists(pr) else float("nan")
print(f"{obj} {variant}: psnr_tm {np.mean(o):.2f} dB, shadow median {np.median(s):.3f} mean {np.mean(s):.3f}, lighting {le:.3f}")
PY
  done
done
