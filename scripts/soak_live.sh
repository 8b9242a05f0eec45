#!/usr/bin/env bash
# Soak run of the live pipeline: a looped folder of 1280x720 frames of the
# synthetic window scene through `nerfar live --headless` for N frames
# (default 10000), every frame processed, with the process's resident memory
# sampled every few seconds. Prints the memory at the first and last samples
# after warm-up, the growth per 1000 frames, and the session's counters
# (frames captured, processed, dropped, errors, reconnections).
#
# Usage: scripts/soak_live.sh NERFAR SCENE OUT [FRAMES]
#   SCENE: a `nerfar demo` output folder (scene.nerf, env.json, *.ssdf, board.json)
set -euo pipefail
exe=$(realpath "$1"); scene=$(realpath "$2"); out=$3; frames=${4:-10000}
mkdir -p "$out"; out=$(realpath "$out")
if [ ! -f "$out/stream/transforms.json" ]; then
  echo "soak: rendering 60 frames of 1280x720 (synthetic window, 1 sample a pixel)"
  "$exe" synth --scene window --res 1280x720 --views 60 --test-views 1 --spp 1 --no-insert --contact-sheet 0 \
    -o "$out/stream" --quiet
fi
rm -rf "$out/session"
"$exe" live --headless --loop --source "images:$out/stream/train" --camera "$out/stream/transforms.json" \
  --scene "$scene" --frames "$frames" --views ar --video "$out/soak.mp4" -o "$out/session" --threads 2 \
  >"$out/live.log" 2>&1 &
pid=$!
echo "seconds,rss_kb" >"$out/rss.csv"
start=$(date +%s)
while kill -0 "$pid" 2>/dev/null; do
  rss=$(awk '/^VmRSS/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)
  [ -n "$rss" ] && echo "$(( $(date +%s) - start )),$rss" >>"$out/rss.csv"
  sleep 5
done
wait "$pid" && status=0 || status=$?
echo "soak: nerfar live exited $status after $(( $(date +%s) - start )) s ($out/live.log)"
/usr/bin/python3 - "$out" "$frames" <<'PY'
import csv, json, sys
out, frames = sys.argv[1], int(sys.argv[2])
rows = [(int(r["seconds"]), int(r["rss_kb"])) for r in csv.DictReader(open(out + "/rss.csv"))]
session = json.load(open(out + "/session/session.json"))
t_end = rows[-1][0] if rows else 0
# Warm-up: the first tenth of the run (models loaded, caches and buffers sized).
warm = [r for r in rows if r[0] >= t_end / 10] or rows
first, last = warm[0], warm[-1]
per_1000 = (last[1] - first[1]) / 1024 / max(1e-9, frames * (last[0] - first[0]) / max(1, t_end) / 1000)
print(f"soak: {frames} frames; resident memory after warm-up {first[1] / 1024:.1f} MB, at the end {last[1] / 1024:.1f} MB, "
      f"peak {max(r[1] for r in rows) / 1024:.1f} MB; growth {per_1000:+.2f} MB per 1000 frames")
print("soak: counters", json.dumps(session["counters"]))
PY
