#!/usr/bin/env bash
# The layering of DESIGN.md ("Layout"), checked on every #include of our code:
#   calib/core  includes nothing of ours but itself; calib/ nothing but calib/.
#   tracking/   includes calib/ and itself.
#   render/M    includes calib/core, itself and the modules its CMakeLists.txt
#               links (nerfar_calib: calib/, nerfar_X: render/X); it may link
#               only calib and the render modules listed before it in
#               render/CMakeLists.txt (the layer order), so the arrows run one
#               way and the includes cannot outrun the link graph.
#   app/        may include everything; nothing includes app/ or tests/.
# Our headers are included as "folder/file.h" from the root (an include in
# <...> or through "../" would escape the check). A module's public headers
# (not *_internal.h) include no third-party header: AprilTag, libcamera, V4L2,
# Embree, OpenCV, OpenEXR, Eigen, assimp, zlib, TBB, GLFW, ImGui, and
# nlohmann/json beyond its forward declaration (calib/core/json.h).
# Every render/ folder is checked; one without a CMakeLists.txt, or not listed
# in render/CMakeLists.txt, is an error. Prints every offence and exits 1 if
# there is any.
set -u
root=${1:-$(dirname "$0")/..}
cd "$root" || exit 2
status=0
fail() {
  echo "layering: $*"
  status=1
}

# Our includes of a folder: "file:line:#include "path"" per line.
our_includes() {
  grep -rnE '#include [<"](calib|tracking|render|app|tests)/' "$1" --include='*.h' --include='*.cpp' --include='*.cu'
}

# folder, allowed include prefixes (extended regex alternatives; '/' follows each)
check() {
  local folder=$1 allowed=$2
  [ -d "$folder" ] || { fail "$folder: folder missing (DESIGN.md's layout has it)"; return; }
  while IFS= read -r hit; do
    fail "$hit (allowed from $folder: $allowed)"
  done < <(our_includes "$folder" | grep -vE "#include \"($allowed)/")
}

# The render modules in layer order, as render/CMakeLists.txt lists them.
render_modules=$(sed -n 's/^foreach(module \(.*\))$/\1/p' render/CMakeLists.txt)
[ -n "$render_modules" ] || fail "render/CMakeLists.txt: no 'foreach(module ...)' list of the render modules"

# Sets `allowed`: a render module's allowed prefixes, from the libraries its CMakeLists.txt links.
render_allowed() {
  local module=$1 earlier=$2 lib
  allowed="calib/core|render/$module"
  for lib in $(grep -v '^ *#' "render/$module/CMakeLists.txt" | grep -oE '\bnerfar_[a-z_]+' | sort -u); do
    case $lib in
      nerfar_add_library | nerfar_core | "nerfar_$module") ;;
      nerfar_calib) allowed="$allowed|calib" ;;
      *)
        local dep=${lib#nerfar_}
        if [[ " $earlier " == *" $dep "* ]]; then
          allowed="$allowed|render/$dep"
        else
          fail "render/$module/CMakeLists.txt: links $lib (expected calib or a render module listed before $module in render/CMakeLists.txt)"
        fi
        ;;
    esac
  done
}

check calib/core 'calib/core'
check calib 'calib'
check tracking 'calib|tracking'
earlier=""
for module in $render_modules; do
  if [ -f "render/$module/CMakeLists.txt" ]; then
    render_allowed "$module" "$earlier"
    check "render/$module" "$allowed"
  else
    fail "render/$module: listed in render/CMakeLists.txt without a CMakeLists.txt"
  fi
  earlier="$earlier $module"
done
for dir in render/*/; do
  module=$(basename "$dir")
  [[ " $render_modules " == *" $module "* ]] || fail "render/$module: not listed in render/CMakeLists.txt (not built, not checked)"
done
check app 'calib|tracking|render|app'

for folder in calib tracking render app; do
  while IFS= read -r hit; do
    fail "$hit (our headers are included as \"folder/file.h\" from the root)"
  done < <(grep -rnE '#include (<(calib|tracking|render|app|tests)/|"\.\./)' "$folder" --include='*.h' --include='*.cpp' --include='*.cu')
  while IFS= read -r hit; do
    fail "$hit (a third-party header in a public header: include it in the .cpp or an *_internal.h)"
  done < <(grep -rnE '#include [<"](apriltag|libcamera|linux/videodev2|libv4l2|embree|opencv2|OpenEXR|Imath|Eigen|assimp|zlib|tbb|oneapi|GLFW|imgui|nlohmann/json\.hpp)' \
             "$folder" --include='*.h' | grep -v '_internal\.h:')
done

[ $status = 0 ] && echo "layering: ok"
exit $status
