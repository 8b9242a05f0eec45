#!/usr/bin/env bash
# Re-measures every figure of docs/BENCHMARKS.md in one run of one build:
# each section's commands (T1, C1, N1, ... as the page names them) with the
# page's thread counts, every output kept under OUT. It trains the NeRFs the
# later sections need, so it takes hours (about 4 with the accurate models, 2
# without): run it alone on a quiet machine (load below ~1) and paste the
# figures into the page. Not part of CI or the tests: it refuses to run when
# CI is set.
set -uo pipefail

usage() {
  cat <<'EOF'
usage: scripts/bench_all.sh --scenes DIR --out DIR [options] [SCENE...]

Runs the commands of docs/BENCHMARKS.md and keeps every output under OUT:
  OUT/machine.txt          commit, `nerfar version`, CPU, load before each section
  OUT/json/*.json          `nerfar bench` figures (names as in the page's tables)
  OUT/time/*.txt           /usr/bin/time -v of the timed commands (wall, CPU)
  OUT/logs/*.log           stdout and stderr of every command
  OUT/models/              the trained models (N1) and env estimates (E4)
  OUT/runs/                render, insert, live and synth outputs (report.json ...)
  OUT/summary.txt          the figures gathered from all of the above (needs python3)

  --scenes DIR     the shared scenes (lamps/, window/, objects/, ...); required
  --out DIR        output folder, created; required
  --build DIR      the Release build to measure (default: build)
  --only LIST      sections to run, comma-separated, in any order (default: all):
                   tracking,calib,nerf,env,ssdf,sg,insert,live,synth,core
  --models DIR     reuse trained models from DIR (SCENE_fast.nerf, SCENE_balanced10.nerf,
                   SCENE_balanced.nerf, SCENE_accurate.nerf; env_SCENE.json) instead of
                   training them: their training times are then not measured
  --skip-accurate  do not train the accurate models (about 1.5 h of the run)
  -h, --help       this text
  SCENE...         the scenes of the NeRF, env and insert sections (default: lamps window)

The env and insert sections need the balanced models (N1) and env estimates (E4):
with --only and without --models they are trained first. Models already in
OUT/models are reused: delete them (or give a new OUT) to measure training again.
Example: scripts/bench_all.sh --scenes ../shared/scenes --out /tmp/bench
EOF
}

scenes_dir="" out="" build="build" only="" models_from="" skip_accurate=0
scene_names=()
while [ $# -gt 0 ]; do
  case "$1" in
    --scenes) scenes_dir=${2:?--scenes needs a folder}; shift 2 ;;
    --out) out=${2:?--out needs a folder}; shift 2 ;;
    --build) build=${2:?--build needs a folder}; shift 2 ;;
    --only) only=${2:?--only needs a list}; shift 2 ;;
    --models) models_from=${2:?--models needs a folder}; shift 2 ;;
    --skip-accurate) skip_accurate=1; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) echo "bench_all: unknown option $1 (see --help)" >&2; exit 2 ;;
    *) scene_names+=("$1"); shift ;;
  esac
done
[ ${#scene_names[@]} -gt 0 ] || scene_names=(lamps window)

die() { echo "bench_all: $*" >&2; exit 2; }
[ -z "${CI:-}" ] || die "CI is set: this script is not for CI (hours of work on a quiet machine)"
[ -n "$scenes_dir" ] && [ -n "$out" ] || { usage >&2; exit 2; }
valid_sections=" tracking calib nerf env ssdf sg insert live synth core "
for section in ${only//,/ }; do
  [[ "$valid_sections" == *" $section "* ]] || die "--only: unknown section '$section' (one of:$valid_sections)"
done
[ -f "$scenes_dir/README.md" ] || die "$scenes_dir: not the shared scenes folder (no README.md)"
for s in "${scene_names[@]}"; do
  [ -f "$scenes_dir/$s/transforms_test.json" ] || die "$scenes_dir/$s: no transforms_test.json (not a scene)"
done
nerfar=$(realpath "$build/app/nerfar" 2>/dev/null) && [ -x "$nerfar" ] || die "$build/app/nerfar: not built"
tests=$(realpath "$build/tests" 2>/dev/null) && [ -d "$tests" ] || die "$build/tests: not built (the tests and micro-benchmarks)"
[ -x /usr/bin/time ] || die "/usr/bin/time (GNU time) is needed for the wall and CPU times"
[ -z "$models_from" ] || [ -d "$models_from" ] || die "$models_from: no such folder"

S=$(realpath "$scenes_dir")
export NERFAR_SCENES=$S
mkdir -p "$out"/{json,time,logs,models,runs}
OUT=$(realpath "$out")
M=$OUT/models G=$OUT/runs/gt R=$OUT/runs
failures=()

wanted() { [ -z "$only" ] || [[ ",$only," == *",$1,"* ]]; }

# run NAME COMMAND...: runs it with its output in logs/NAME.log; a failure is
# recorded and the run goes on (one failing figure must not cost the others).
run() {
  local name=$1; shift
  echo "  $name: $*"
  if ! "$@" >"$OUT/logs/$name.log" 2>&1; then
    failures+=("$name")
    echo "  $name: FAILED (see logs/$name.log)" >&2
  fi
}
# timed NAME COMMAND...: the same under /usr/bin/time -v (time/NAME.txt).
timed() {
  local name=$1; shift
  run "$name" /usr/bin/time -v -o "$OUT/time/$name.txt" "$@"
}

section() {
  echo "== $1  ($(date -u '+%F %T UTC'), load $(cut -d' ' -f1-3 /proc/loadavg))"
  echo "$1: $(date -u '+%F %T UTC'), load $(cut -d' ' -f1-3 /proc/loadavg)" >>"$OUT/machine.txt"
  local load1
  load1=$(cut -d' ' -f1 /proc/loadavg)
  awk -v l="$load1" 'BEGIN { exit !(l > 1.5) }' && echo "  warning: load $load1: times will read high"
}

{
  echo "commit: $(git -C "$(dirname "$0")/.." rev-parse HEAD 2>/dev/null || echo unknown)"
  echo "binary: $nerfar"
  "$nerfar" version
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-), $(nproc) cores"
  echo "scenes: $S (${scene_names[*]})"
} >"$OUT/machine.txt" 2>&1

# The models of N1, trained once (or taken from --models). These helpers set a
# variable instead of printing, so that they run in this shell: a training's
# failure is then recorded like any other.
model() {  # SCENE VARIANT: sets MODEL to the model's path, trained if missing
  local s=$1 v=$2 path="$M/$1_$2.nerf"
  if [ ! -f "$path" ] && [ -n "$models_from" ] && [ -f "$models_from/$1_$2.nerf" ]; then
    ln -sf "$(realpath "$models_from/$1_$2.nerf")" "$path"
  fi
  if [ ! -f "$path" ]; then
    case "$v" in
      fast) timed "N1_${s}_fast" "$nerfar" train "$S/$s" -o "$path" --preset fast --restart ;;
      balanced10) timed "N1_${s}_balanced10" "$nerfar" train "$S/$s" -o "$path" --preset balanced --minutes 10 --restart ;;
      balanced) timed "N1_${s}_balanced" "$nerfar" train "$S/$s" -o "$path" --preset balanced --restart ;;
      accurate) timed "N1_${s}_accurate" "$nerfar" train "$S/$s" -o "$path" --preset accurate --restart \
                  --checkpoint-seconds 1200 ;;
    esac
  fi
  MODEL=$path
}
env_estimate() {  # SCENE: sets ENV_JSON to its env.json (E4), estimated if missing
  local s=$1 path="$M/env_$1.json"
  if [ ! -f "$path" ] && [ -n "$models_from" ] && [ -f "$models_from/env_$s.json" ]; then
    cp "$models_from/env_$s.json" "$path"
  fi
  if [ ! -f "$path" ]; then
    model "$s" balanced
    timed "E4_$s" "$nerfar" env "$MODEL" -o "$path" --threads 2
  fi
  ENV_JSON=$path
}
models_list() {  # VARIANT: sets MODELS to lamps=PATH,window=PATH for NERFAR_BENCH_*_MODELS
  local s
  MODELS=""
  for s in "${scene_names[@]}"; do model "$s" "$1"; MODELS+="${MODELS:+,}$s=$MODEL"; done
}

# ------------------------------------------------------------------ tracking
if wanted tracking; then
  section tracking
  run T1 "$nerfar" bench tracking --threads 2 --json "$OUT/json/tracking.json"
  run T2 "$tests/tracking/tracking_test" --gtest_filter=SharedScenes.TestViewsMedianError
fi

# ---------------------------------------------------------------- calibration
if wanted calib; then
  section calib
  run C1 "$tests/calib/calib_test" '--gtest_filter=Intrinsics.*:Hdr.*'
  timed C2 "$tests/integration/integration_test" --gtest_filter=Capture.BracketsBecomeAnHdrDatasetTheTrainerAccepts
fi

# ----------------------------------------------------------------------- nerf
if wanted nerf; then
  section nerf
  variants=(fast balanced10 balanced)
  [ $skip_accurate = 1 ] || variants+=(accurate)
  for s in "${scene_names[@]}"; do
    for v in "${variants[@]}"; do
      model "$s" "$v"
      run "N2_${s}_$v" "$nerfar" render "$MODEL" --dataset "$S/$s" -o "$R/render_${s}_$v"
    done
    model "$s" balanced10
    for q in live preview; do
      run "N2_${s}_balanced10_$q" "$nerfar" render "$MODEL" --dataset "$S/$s" \
        -o "$R/render_${s}_balanced10_$q" --quality "$q"
    done
    run "N2_${s}_balanced10_float" "$nerfar" render "$MODEL" --dataset "$S/$s" \
      -o "$R/render_${s}_balanced10_float" --no-render-copy
  done
  models_list balanced10
  run N3 env NERFAR_BENCH_NERF_MODELS="$MODELS" "$nerfar" bench nerf --threads 2 --json "$OUT/json/nerf.json"
fi

# ------------------------------------------------------------------------ env
if wanted env; then
  section env
  for s in "${scene_names[@]}"; do env_estimate "$s"; done
  models_list balanced
  balanced_models=$MODELS
  run E1 env NERFAR_BENCH_ENV_MODELS="$balanced_models" \
    "$nerfar" bench env --threads 2 --json "$OUT/json/env.json"
  run E2 env NERFAR_BENCH_ENV_TRADE=1 NERFAR_BENCH_ENV_TRADE_ONLY=1 NERFAR_BENCH_ENV_MODELS="$balanced_models" \
    "$nerfar" bench env --threads 2 --json "$OUT/json/env_trade.json"
  run E3 env -u NERFAR_BENCH_ENV_MODELS "$nerfar" bench env --threads 2 --json "$OUT/json/env_synthetic.json"
fi

# ----------------------------------------------------------------------- ssdf
if wanted ssdf; then
  section ssdf
  run B1 "$nerfar" bench ssdf --threads 2 --json "$OUT/json/ssdf.json"
  timed B2 "$nerfar" bake "$S/objects/monkey_diffuse.json" -o "$R/monkey_fast.ssdf" --preset fast --threads 2
fi

# ------------------------------------------------------------------------- sg
if wanted sg; then
  section sg
  run G1 "$nerfar" bench sg --threads 1 --json "$OUT/json/sg.json"
  for simd in default avx2 baseline; do
    prefix=(env)
    [ $simd = default ] || prefix=(env "NERFAR_SG_SIMD=$simd")
    run "G2_$simd" "${prefix[@]}" "$tests/bench/sg_micro_bench" --benchmark_filter=Shade \
      --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
      --benchmark_out="$OUT/json/sg_micro_$simd.json" --benchmark_out_format=json
  done
  if command -v valgrind >/dev/null; then
    for material in 0 1; do for lobes in 8 32 64; do for repeats in 1 11; do
      run "G3_batch_${material}_${lobes}_$repeats" valgrind --tool=callgrind --callgrind-out-file=/dev/null \
        "$tests/bench/sg_shade_driver" batch "$material" "$lobes" "$repeats"
    done; done; done
  else
    echo "  G3: valgrind not installed: instruction counts skipped"
  fi
fi

# --------------------------------------------------------------------- insert
if wanted insert; then
  section insert
  # I0: the low-noise backgrounds under the dataset's names, the objects baked balanced.
  for s in "${scene_names[@]}"; do
    mkdir -p "$G/frames_$s"
    for bg in "$S/$s"/insert/bg_*.exr; do
      name=$(basename "$bg"); ln -sf "$bg" "$G/frames_$s/r_${name#bg_}"
    done
  done
  for o in monkey_diffuse sphere_glossy; do
    [ -f "$G/$o.ssdf" ] || run "I0_$o" "$nerfar" bake "$S/objects/$o.json" -o "$G/$o.ssdf" --preset balanced --threads 2
  done
  for s in "${scene_names[@]}"; do
    model "$s" balanced
    nerf=$MODEL
    env_estimate "$s"
    env_json=$ENV_JSON
    for o in monkey_diffuse sphere_glossy; do
      [ -d "$S/$s/insert/$o" ] || continue
      common=(--object "$G/$o.ssdf" --pose "$S/$s/insert/$o/pose.json" --dataset "$S/$s" --frames "$G/frames_$s"
              --truth "$S/$s/insert/$o" --threads 2 --quiet)
      for p in balanced fast accurate; do
        run "I1_${s}_${o}_$p" "$nerfar" insert "${common[@]}" -o "$R/gt_${s}_${o}_$p" --truth-geometry \
          --light-probe "$S/$s/insert/$o/probe.exr" --probe-distances "$nerf" --preset "$p"
        run "I2_${s}_${o}_${p}_full" "$nerfar" insert "${common[@]}" -o "$R/e2e_${s}_${o}_${p}_full" \
          --nerf "$nerf" --env "$env_json" --light-source full --preset "$p"
      done
      for l in env near; do
        run "I2_${s}_${o}_balanced_$l" "$nerfar" insert "${common[@]}" -o "$R/e2e_${s}_${o}_balanced_$l" \
          --nerf "$nerf" --env "$env_json" --light-source "$l" --preset balanced
      done
    done
  done
  for i in 1 2; do
    run "I3_t2_run$i" env NERFAR_BENCH_INSERT_GT=0 NERFAR_BENCH_INSERT_PRESETS=fast,balanced,accurate \
      "$nerfar" bench insert --threads 2 --json "$OUT/json/insert_t2_run$i.json"
  done
  run I3_t1 env NERFAR_BENCH_INSERT_GT=0 NERFAR_BENCH_INSERT_PRESETS=fast,balanced,accurate \
    "$nerfar" bench insert --threads 1 --json "$OUT/json/insert_t1.json"
  for s in "${scene_names[@]}"; do
    model "$s" balanced
    run "I4_$s" env NERFAR_BENCH_INSERT_NERF="$MODEL" NERFAR_BENCH_INSERT_PRESETS=none \
      NERFAR_BENCH_INSERT_GT=0 "$nerfar" bench insert --threads 2 --json "$OUT/json/insert_light_$s.json"
  done
fi

# ----------------------------------------------------------------------- live
if wanted live; then
  section live
  demo=$R/demo_out
  timed L1 "$nerfar" demo --headless -o "$demo" --restart
  for p in fast balanced; do
    run "L2_$p" "$nerfar" live --headless --realtime --views ar --source synthetic:window,spp=1 --scene "$demo" \
      --preset "$p" -o "$R/live_$p" --frames 40
  done
  run L3 "$nerfar" live --headless --source synthetic:window,spp=1 --scene "$demo" -o "$R/live_stepped" --frames 60
  run L4 "$nerfar" render "$demo/scene.nerf" --dataset "$demo/dataset" -o "$R/demo_render"
  timed L1_quick "$nerfar" demo --quick --headless -o "$R/demo_quick" --restart
  run L4_quick "$nerfar" render "$R/demo_quick/scene.nerf" --dataset "$R/demo_quick/dataset" -o "$R/demo_quick_render"
  if command -v xvfb-run >/dev/null; then
    run L5 xvfb-run -a "$nerfar" live --source synthetic:window,spp=1 --scene "$demo" -o "$R/live_window" \
      --frames 8 --auto-place
  else
    echo "  L5: xvfb-run not installed: the window's figures skipped"
  fi
fi

# ---------------------------------------------------------------------- synth
if wanted synth; then
  section synth
  for s in lamps window; do
    timed "Y1_$s" "$nerfar" synth --scene "$s" -o "$R/synth_$s" --spp 16 --insert-spp 32 --threads 2
  done
  run Y2 "$nerfar" bench synth --threads 2 --json "$OUT/json/synth.json"
fi

# ----------------------------------------------------------------------- core
if wanted core; then
  section core
  run K1 "$nerfar" bench core --threads 1 --json "$OUT/json/core.json"
fi

# -------------------------------------------------------------------- summary
if command -v python3 >/dev/null; then
  python3 - "$OUT" >"$OUT/summary.txt" <<'EOF'
import glob, json, os, re, sys
out = sys.argv[1]
def read(path):
    try:
        return json.load(open(path))
    except Exception as error:
        return {"error": str(error)}
print("# bench figures (json/): stage figure value unit note")
for path in sorted(glob.glob(os.path.join(out, "json", "*.json"))):
    data = read(path)
    for stage, body in data.get("stages", {}).items():
        for f in body.get("figures", []):
            print(f"{os.path.basename(path)}\t{stage}\t{f['name']}\t{f['value']:.6g}\t{f['unit']}\t{f['note']}")
    for b in data.get("benchmarks", []):
        print(f"{os.path.basename(path)}\tmicro\t{b['name']}\t{b.get('cpu_time', 0):.6g}\t{b.get('time_unit', '')}\tCPU time")
print("\n# timed commands (time/): wall, user + system CPU seconds")
for path in sorted(glob.glob(os.path.join(out, "time", "*.txt"))):
    text = open(path).read()
    wall = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", text)
    user = re.search(r"User time \(seconds\): (\S+)", text)
    system = re.search(r"System time \(seconds\): (\S+)", text)
    cpu = float(user.group(1)) + float(system.group(1)) if user and system else float("nan")
    print(f"{os.path.basename(path)[:-4]}\twall {wall.group(1) if wall else '?'}\tCPU {cpu:.1f} s")
print("\n# models (models/): size in MB")
for path in sorted(glob.glob(os.path.join(out, "models", "*.nerf"))):
    print(f"{os.path.basename(path)}\t{os.path.getsize(path) / 1e6:.1f} MB")
for path in sorted(glob.glob(os.path.join(out, "models", "env_*.json"))):
    env = read(path)
    energy = env.get("energy", {})
    print(f"{os.path.basename(path)}\tnegligible {env.get('negligible')}\tevidence {energy.get('evidence')}"
          f" / needed {energy.get('evidence_needed')}")
print("\n# reports (runs/*/report.json)")
keys = ["mean_psnr_tm_reference_db", "surface_depth_median_error_m", "model_file_mb",
        "mean_object_psnr_tm_db", "pooled_object_psnr_tm_db", "mean_shadow_error", "median_shadow_error",
        "lighting_error"]
for path in sorted(glob.glob(os.path.join(out, "runs", "**", "report.json"), recursive=True)):
    report = read(path)
    found = {k: report[k] for k in keys if isinstance(report.get(k), (int, float))}
    if not found:  # a live session's report: print its top-level numbers
        found = {k: v for k, v in report.items() if isinstance(v, (int, float))}
    print(os.path.relpath(path, out) + "\t" + "  ".join(f"{k} {v:.6g}" for k, v in found.items()))
print("\n# instruction counts (logs/G3_*): Collected")
for path in sorted(glob.glob(os.path.join(out, "logs", "G3_*.log"))):
    m = re.search(r"Collected : (\d+)", open(path).read())
    print(f"{os.path.basename(path)[:-4]}\t{m.group(1) if m else '?'}")
print("  (instructions per pixel = (R 11 - R 1) / 2560 for each material and lobe count)")
EOF
  echo "summary: $OUT/summary.txt"
else
  echo "python3 not installed: no summary; the figures are in $OUT/json, time, runs and logs"
fi

if [ ${#failures[@]} -gt 0 ]; then
  echo "bench_all: ${#failures[@]} command(s) failed: ${failures[*]}" >&2
  exit 1
fi
echo "bench_all: done; $OUT"
