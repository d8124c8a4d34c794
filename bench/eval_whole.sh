#!/usr/bin/env bash
# `trisplat eval` on 1M <-> 1M points as a whole process against scipy's cKDTree compute
# (issue #32 item 4: >= 6x). For each mesh given: a Taubin-smoothed copy sampled with one
# seed as the prediction, the mesh sampled with another as the ground truth (`trisplat sample`,
# binary PLY with normals); then ROUNDS rounds of each binary's `eval PRED GT --json -q` under
# /usr/bin/time (wall and CPU seconds: the whole process, both files read) and
# bench/python/eval_scipy.py (its compute alone: both cKDTree(workers=-1) builds and queries
# and the metric arithmetic, the PLYs read before the timer; wall and CPU seconds). Prints one
# line per run, the load average, and each binary's chamfer_l1 beside scipy's. A MESH given as
# PRED_MESH:GT_MESH samples the two meshes themselves instead (e.g. ICT FaceKit
# mouthSmile_L.obj:eyeBlink_L.obj, or the FLAME scan against the FLAME template).
#
#     cargo build --release -p trisplat-cli
#     bash bench/eval_whole.sh OUT_DIR PYTHON ROUNDS BINARY [BINARY ...] -- MESH [MESH ...]
#         # e.g. bash bench/eval_whole.sh /tmp/ew /tmp/refvenv/bin/python 3 \
#         #   old/trisplat target/release/trisplat -- ../shared/data/meshes/spot/spot_triangulated.obj
#
# Needs numpy and scipy in PYTHON. The first binary generates the inputs.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:?output folder}"
python="${2:?python with scipy}"
rounds="${3:?rounds}"
shift 3
binaries=()
while [ "$#" -gt 0 ] && [ "$1" != "--" ]; do
  binaries+=("$(realpath "$1")")
  shift
done
shift || true
[ "$#" -gt 0 ] || { echo "no meshes given (after --)" >&2; exit 2; }
mkdir -p "$out"
gen="${binaries[0]}"
seed=100
names=()
for mesh in "$@"; do
  seed=$((seed + 2))
  if [[ "$mesh" == *:* ]]; then
    pred_mesh="${mesh%%:*}"
    mesh="${mesh#*:}"
    name="$(basename "${pred_mesh%.*}")_vs_$(basename "${mesh%.*}")"
  else
    pred_mesh=""
    name="$(basename "${mesh%.*}")"
  fi
  names+=("$name")
  if [ ! -f "$out/${name}_gt.ply" ]; then
    if [ -z "$pred_mesh" ]; then
      pred_mesh="$out/${name}_taubin.ply"
      "$gen" smooth "$mesh" -o "$pred_mesh" --method taubin --iterations 10 -q
    fi
    "$gen" sample "$pred_mesh" -n 1000000 --seed "$seed" -o "$out/${name}_pred.ply" -q
    "$gen" sample "$mesh" -n 1000000 --seed $((seed + 1)) -o "$out/${name}_gt.ply" -q
  fi
done
uptime
for round in $(seq "$rounds"); do
  for name in "${names[@]}"; do
    pred="$out/${name}_pred.ply"
    gt="$out/${name}_gt.ply"
    for b in "${binaries[@]}"; do
      /usr/bin/time -f "round $round $name $(basename "$(dirname "$(dirname "$b")")")/$(basename "$b"): %e s wall, %U user, %S sys, %M KB" \
        "$b" eval "$pred" "$gt" --json -q > "$out/${name}_$(echo "$b" | md5sum | cut -c1-8).json"
    done
    "$python" "$root/bench/python/eval_scipy.py" points "$pred" "$gt" 0.001 | tail -1 \
      | "$python" -c "import json, sys; d = json.load(sys.stdin); print(f'round $round $name scipy compute: {d[\"seconds\"]:.2f} s wall, {d[\"cpu_seconds\"]:.2f} CPU-s, chamfer_l1 {d[\"chamfer_l1\"]!r}')"
  done
  uptime
done
for name in "${names[@]}"; do
  for b in "${binaries[@]}"; do
    "$python" -c "import json, sys; print('$name', sys.argv[2], 'chamfer_l1', repr(json.load(open(sys.argv[1]))['chamfer_l1']))" \
      "$out/${name}_$(echo "$b" | md5sum | cut -c1-8).json" "$b"
  done
done
