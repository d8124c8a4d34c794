#!/usr/bin/env bash
# Real glTF clients on trisplat's animated glTFs (issue #31), for .ci/run: the LAM fixture
# (fixtures/data/lam_mini, its 10-frame expression track) extracted with --topology adaptive
# (one morph-target mesh per method) and --topology per-frame (alpha: one node per frame), the
# default glTF storage (meshopt); the tsdf frames converted again with --gltf-compression
# none and quantize. check.mjs then runs the Khronos glTF-Validator (0 errors) and three.js's
# GLTFLoader + AnimationMixer (every vertex of frame k within 1e-4 of the frame's bounding-box
# diagonal) on each file. The rig (--targets rig, --topology fixed): the validator again, and
# three.js's SkinnedMesh (morph targets, then bones: getVertexPosition) at frames 0, 3, 6 and 9
# against trisplat's own evaluation of the same file (convert --clip 0 --time T, geometry's
# glTF evaluator), within 1e-4 of the diagonal. Pinned npm versions: package.json + package-lock.json (npm ci).
#
# usage: run.sh TRISPLAT_BINARY      (about 15 s on 2 cores)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
trisplat=$(realpath "$1")
lam="$here/../../../fixtures/data/lam_mini"
command -v node >/dev/null || { echo "run.sh: needs node and npm (Debian: nodejs)" >&2; exit 1; }
(cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
extract() {
    "$trisplat" extract --avatar "$lam" --animation "$lam/expression.json" -q \
        --consistency-views 0 --targets meshes,glb,report "$@" >/dev/null
}
extract --method tsdf,delaunay,alpha --topology adaptive -o "$work/adaptive"
extract --method alpha --topology per-frame -o "$work/per_frame"
for kind in none quantize; do
    "$trisplat" convert "$work/adaptive/tsdf" "$work/tsdf_$kind.glb" --any-topology \
        --gltf-compression "$kind" -q
done
cd "$here"
a="$work/adaptive"
node check.mjs --report "$a/report.json" \
    "$a/tsdf.glb=$a/tsdf" "$a/delaunay.glb=$a/delaunay" "$a/alpha.glb=$a/alpha" \
    "$work/tsdf_none.glb=$a/tsdf" "$work/tsdf_quantize.glb=$a/tsdf"
node check.mjs --report "$work/per_frame/report.json" "$work/per_frame/alpha.glb=$work/per_frame/alpha"

# The rig of the first key mesh, played by three.js and by trisplat's own evaluator.
"$trisplat" extract --avatar "$lam" --animation "$lam/expression.json" -q --consistency-views 0 \
    --method tsdf,delaunay --topology fixed --targets rig,report -o "$work/rig" >/dev/null
read -r -a times < <(node -e 'const r = JSON.parse(require("fs").readFileSync(process.argv[1]));
  console.log(r.frame_times.join(" "))' "$work/rig/report.json")
picked=()
pairs=()
for k in 0 3 6 9; do picked+=("${times[$k]}"); done
for m in tsdf delaunay; do
    mkdir -p "$work/rig_$m"
    for k in 0 3 6 9; do
        "$trisplat" convert "$work/rig/${m}_rig.glb" "$work/rig_$m/frame_00000$k.ply" \
            --clip 0 --time "${times[$k]}" -q
    done
    pairs+=("$work/rig/${m}_rig.glb=$work/rig_$m")
done
node check.mjs --times "$(IFS=,; echo "${picked[*]}")" "${pairs[@]}"
