#!/usr/bin/env bash
# Tests tests/check_layering.sh on a small tree of our layout: the tree as it
# should be passes, and each breach of DESIGN.md's layering, made one at a
# time, fails with a line naming it.
set -u
check=$(cd "$(dirname "$0")" && pwd)/check_layering.sh
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failures=0

# A tree that keeps every rule: render lists mesh before sg; mesh links calib,
# sg links only core; app includes everything.
make_tree() {
  rm -rf "$work/tree"
  mkdir -p "$work/tree"/{calib/core,tracking,render/mesh,render/sg,app}
  cd "$work/tree" || exit 2
  echo '#include <string>' >calib/core/error.h
  echo '#include "calib/core/error.h"' >calib/camera.h
  printf '#include "calib/camera.h"\n#include "tracking/tag.h"\n' >tracking/pose.h
  echo '#include "calib/core/error.h"' >tracking/tag.h
  printf 'foreach(module mesh sg)\n  add_subdirectory(${module})\nendforeach()\n' >render/CMakeLists.txt
  echo 'nerfar_add_library(NAME mesh SRCS mesh.cpp DEPS nerfar_calib nerfar_core)' >render/mesh/CMakeLists.txt
  printf '#include "calib/camera.h"\n#include "render/mesh/mesh.h"\n' >render/mesh/mesh.h
  echo '#include <opencv2/core.hpp>' >render/mesh/mesh.cpp
  echo '#include <Eigen/Core>' >render/mesh/mesh_internal.h
  echo 'nerfar_add_library(NAME sg SRCS sg.cpp DEPS nerfar_core)' >render/sg/CMakeLists.txt
  echo '#include "calib/core/error.h"' >render/sg/sg.h
  printf '#include "render/sg/sg.h"\n#include "render/mesh/mesh.h"\n#include "tracking/pose.h"\n#include "app/cli.h"\n' \
    >app/main.cpp
  echo '#include <nlohmann/json_fwd.hpp>' >calib/core/json.h
}

# name, expected exit status, pattern the output must hold
expect() {
  local name=$1 status=$2 pattern=$3 output code
  output=$(bash "$check" "$work/tree" 2>&1)
  code=$?
  if [ "$code" != "$status" ] || ! grep -qE -- "$pattern" <<<"$output"; then
    echo "FAIL $name: exit $code (expected $status), output:"
    sed 's/^/  /' <<<"$output"
    failures=$((failures + 1))
  else
    echo "ok   $name"
  fi
}

make_tree
expect "the tree as it should be" 0 'layering: ok'

make_tree; echo '#include "calib/camera.h"' >>calib/core/error.h
expect "calib/core includes calib" 1 'calib/core/error.h:2:.*calib/camera.h'
make_tree; echo '#include "tracking/tag.h"' >>calib/camera.h
expect "calib includes tracking" 1 'calib/camera.h:2:.*tracking/tag.h'
make_tree; echo '#include "render/sg/sg.h"' >>tracking/tag.h
expect "tracking includes render" 1 'tracking/tag.h:2:.*render/sg/sg.h'
make_tree; echo '#include "calib/camera.h"' >>render/sg/sg.h
expect "render/sg includes calib without linking it" 1 'render/sg/sg.h:2:.*calib/camera.h'
make_tree; echo '#include "render/sg/sg.h"' >>render/mesh/mesh.h
expect "render/mesh includes render/sg without linking it" 1 'render/mesh/mesh.h:3:.*render/sg/sg.h'
make_tree; echo 'nerfar_add_library(NAME mesh SRCS mesh.cpp DEPS nerfar_sg nerfar_calib)' >render/mesh/CMakeLists.txt
expect "render/mesh links a later module" 1 'render/mesh/CMakeLists.txt: links nerfar_sg'
make_tree; echo '#include "tracking/tag.h"' >>render/sg/sg.h
expect "render includes tracking" 1 'render/sg/sg.h:2:.*tracking/tag.h'
make_tree; echo '#include "app/cli.h"' >>render/sg/sg.h
expect "render includes app" 1 'render/sg/sg.h:2:.*app/cli.h'
make_tree; echo '#include "tests/support/support.h"' >>render/sg/sg.h
expect "render includes tests" 1 'render/sg/sg.h:2:.*tests/support'
make_tree; echo '#include "tests/support/support.h"' >>app/main.cpp
expect "app includes tests" 1 'app/main.cpp:5:.*tests/support'
make_tree; echo '#include <render/mesh/mesh.h>' >>render/sg/sg.h
expect "an include in <...>" 1 'render/sg/sg.h:2:.*<render/mesh'
make_tree; echo '#include "../mesh/mesh.h"' >>render/sg/sg.h
expect "an include through ../" 1 'render/sg/sg.h:2:.*\.\./mesh'
make_tree; echo '#include <opencv2/core.hpp>' >>render/mesh/mesh.h
expect "OpenCV in a public header" 1 'render/mesh/mesh.h:3:.*opencv2'
make_tree; echo '#include <apriltag.h>' >>tracking/tag.h
expect "AprilTag in a public header" 1 'tracking/tag.h:2:.*apriltag'
make_tree; echo '#include <nlohmann/json.hpp>' >>calib/core/json.h
expect "nlohmann/json.hpp in a public header" 1 'calib/core/json.h:2:.*nlohmann/json.hpp'
make_tree; mkdir render/extra && echo 'nerfar_add_library(NAME extra SRCS e.cpp DEPS nerfar_core)' >render/extra/CMakeLists.txt
expect "a render folder not listed" 1 'render/extra: not listed'
make_tree; rm render/sg/CMakeLists.txt
expect "a listed render folder without CMakeLists.txt" 1 'render/sg: listed in render/CMakeLists.txt without'
make_tree; rm -r tracking
expect "a layer's folder missing" 1 'tracking: folder missing'

[ $failures = 0 ] && echo "check_layering_test: all cases as expected"
exit $((failures > 0))
