#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine (packages + Release build, via setup.sh),
# runs the bounded libFuzzer runs of every reader of untrusted bytes (clang
# build of calib/ and the render/ readers, ASan + UBSan), then the whole
# GoogleTest suite through ctest; prints how many tests were skipped and which.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

# ctest's "(Skipped)" lines of a log: their count and names.
report_skipped() {
  local skipped
  skipped=$(grep -c '(Skipped)$' "$1" || true)
  echo "== skipped tests: ${skipped}"
  grep '(Skipped)$' "$1" || true
}

echo "== fuzz: libFuzzer + ASan/UBSan on the readers (${NERFAR_FUZZ_SECONDS:-20} s per target)"
cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
  -DNERFAR_FUZZ=ON -DNERFAR_READERS_ONLY=ON -DNERFAR_BENCHMARKS=OFF \
  -DNERFAR_FUZZ_SECONDS="${NERFAR_FUZZ_SECONDS:-20}" >/dev/null
cmake --build build-fuzz --parallel "$(nproc)" --target \
  fuzz_json fuzz_exr fuzz_image fuzz_dataset fuzz_nerf fuzz_checkpoint fuzz_ssdf fuzz_mesh
ctest --test-dir build-fuzz -L fuzz --output-on-failure --parallel "$(nproc)"

echo "== tests"
status=0
ctest --test-dir build --output-on-failure --parallel "$(nproc)" --timeout 1500 2>&1 | tee build/ctest.log || status=$?
report_skipped build/ctest.log
exit "$status"
