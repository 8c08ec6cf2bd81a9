#!/usr/bin/env bash
# Real surface assets for `mochi mesh`, from Debian's assimp-testmodels (the Open Asset Import
# Library's test models; BSD-3-clause unless a model's own note says otherwise), converted to
# glTF binary by Debian's assimp-utils (`assimp export ... -fglb2`) where they are in another
# format. Nothing is committed: the files are made under out/assets/src/.
#
#   scripts/assets.sh fetch            # install the two packages when missing, convert the models
#   scripts/assets.sh mesh [ARGS...]   # fetch, then `mochi mesh` each (ARGS go to every call)
#   scripts/assets.sh tetgen           # after `mesh`: TetGen on each repaired surface, for comparison
#
# The models:
#   human     BLEND/HUMAN.blend, 8,560 triangles, a human body ("(c) 2010, Tobias Rittig.
#             Redistribution and reuse allowed for any purpose", HUMAN.source.txt beside it)
#   epileptic X/BCN_Epileptic.X, 5,126 triangles, a body in three named meshes (lower body,
#             upper body, head; BSD-3-clause)
#   dino      X/fromtruespace_bin32.x, 6,656 triangles, a toy dinosaur on four feet
#             ("FeedTheDinoGPU"; BSD-3-clause), three small holes: meshed with --accept-defects
#   wuson     OBJ/WusonOBJ.obj, 3,732 triangles, a toy creature (BSD-3-clause), read as OBJ
#   sphere-hole STL/sphereWithHole.stl, an open sphere (BSD-3-clause): refused unless
#             --accept-defects
set -euo pipefail
cd "$(dirname "$0")/.."
models=/usr/share/assimp/models
src=out/assets/src
need=()
[ -d "$models" ] || need+=(assimp-testmodels)
command -v assimp >/dev/null || need+=(assimp-utils)
if [ ${#need[@]} -gt 0 ]; then
  echo "== apt-get install ${need[*]}" >&2
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo=sudo
  $sudo apt-get install -y --no-install-recommends "${need[@]}" >&2
fi
mkdir -p "$src"
convert() { # NAME MODEL: a glTF binary of the model
  [ -s "$src/$1.glb" ] || assimp export "$models/$2" "$src/$1.glb" -fglb2 >/dev/null
}
convert human BLEND/HUMAN.blend
convert epileptic X/BCN_Epileptic.X
convert dino X/fromtruespace_bin32.x
cp -f "$models/OBJ/WusonOBJ.obj" "$src/wuson.obj"
cp -f "$models/STL/sphereWithHole.stl" "$src/sphere-hole.stl"

mochi() { cargo run --release -q -p mochi-trainer -- "$@"; }
case "${1:-fetch}" in
  fetch) ls -l "$src" ;;
  mesh)
    shift
    for asset in human.glb dino.glb epileptic.glb wuson.obj sphere-hole.stl; do
      echo "== mochi mesh $src/$asset $*"
      mochi mesh "$src/$asset" "$@" || echo "(refused: see above)"
    done
    ;;
  tetgen)
    for name in human dino epileptic wuson sphere-hole; do
      surface=out/assets/$name/$name.surface.npz
      [ -f "$surface" ] || continue
      echo "== tetgen $surface"
      scripts/tetwild.sh tetgen "$surface" "out/assets/$name/$name.tetgen.mesh" || echo "(tetgen failed)"
    done
    ;;
  *) sed -n '2,/^set -e/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2 ;;
esac
