#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine (packages + Release build, via setup.sh),
# runs the bounded libFuzzer runs of the file readers (clang build of calib/),
# then the whole GoogleTest suite through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

echo "== fuzz: libFuzzer + ASan/UBSan on the readers (${NERFAR_FUZZ_SECONDS:-20} s per target)"
cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
  -DNERFAR_FUZZ=ON -DNERFAR_READERS_ONLY=ON -DNERFAR_BENCHMARKS=OFF \
  -DNERFAR_FUZZ_SECONDS="${NERFAR_FUZZ_SECONDS:-20}" >/dev/null
cmake --build build-fuzz --parallel "$(nproc)" --target fuzz_json fuzz_exr fuzz_dataset
ctest --test-dir build-fuzz -L fuzz --output-on-failure

echo "== tests"
ctest --test-dir build --output-on-failure --parallel "$(nproc)" --timeout 1500
