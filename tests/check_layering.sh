#!/usr/bin/env bash
# Keeps the dependency arrows one way (DESIGN.md): calib -> nothing of ours,
# tracking -> calib, render -> calib, app -> everything. Within render/, a
# module may include only the modules listed for it below. Prints every
# offending include and exits 1 if there is any.
set -u
root=${1:-$(dirname "$0")/..}
cd "$root" || exit 2
status=0
check() {  # folder, allowed include prefixes (regex)
  local folder=$1 allowed=$2
  [ -d "$folder" ] || return 0
  while IFS= read -r hit; do
    echo "layering: $hit (allowed from $folder: $allowed)"
    status=1
  done < <(grep -rnE '#include "(calib|tracking|render|app)/' "$folder" --include='*.h' --include='*.cpp' --include='*.cu' |
           grep -vE "#include \"($allowed)/")
}
check calib 'calib'
check tracking 'calib|tracking'
check render/sg 'calib|render/sg'
check render/mesh 'calib|render/mesh'
check render/ssdf 'calib|render/mesh|render/ssdf'
check render/nerf 'calib|render/nerf'
check render/synth 'calib|render/mesh|render/sg|render/synth'
check render/lighting 'calib|render/sg|render/nerf|render/lighting'
check render/insert 'calib|render/mesh|render/sg|render/nerf|render/ssdf|render/lighting|render/insert'
[ $status = 0 ] && echo "layering: ok"
exit $status
