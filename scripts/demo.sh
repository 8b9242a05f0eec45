#!/usr/bin/env bash
# The README's first command: from a fresh machine to a running AR sequence.
# Sets the machine up (scripts/setup.sh: packages + build), then runs
# `nerfar demo`: synth (a small 'window' scene with ground truth) -> train
# (fast NeRF) -> env (environment SGs) -> bake (the torus's SSDF) -> live on
# the synthetic camera stream, tracked from its own rendered tags. With a
# display the live window opens; without one it writes OUT_DIR/demo.mp4,
# OUT_DIR/contact_sheet.png and OUT_DIR/timing.json (and the session report in
# OUT_DIR/session/). Re-running reuses finished stages.
# Usage: scripts/demo.sh [OUT_DIR] [nerfar demo options, e.g. --headless]
# (default OUT_DIR demo_out; NERFAR_DEMO_MINUTES caps training at that many
# minutes, default: the fast preset's whole schedule, ~1 minute on a quiet
# 2-core machine).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-demo_out}
[ $# -gt 0 ] && shift
if [ -n "${NERFAR_DEMO_MINUTES:-}" ]; then
  exec build/app/nerfar demo -o "$out" --minutes "$NERFAR_DEMO_MINUTES" "$@"
fi
exec build/app/nerfar demo -o "$out" "$@"
