#!/usr/bin/env bash
# Opacity meshing at scale (issue #34, "Scale"): flat Gaussians bound densely to a scanned mesh
# (`trisplat-bench gaussian-scene`), meshed by `trisplat opacity-mesh` with GOF's field and with
# `--field median`, each whole process under `/usr/bin/time -v` (wall, user + sys, peak RSS), and
# the mesh scored against the scan (`trisplat eval MESH SCAN --surface`).
#
#   bench/opacity_scale.sh WORK [SIZES...] [-- EXTRA opacity-mesh ARGS]
#
# Environment: TRISPLAT (default target/release/trisplat), TRISPLAT_BENCH (default
# target/release/trisplat-bench), SCAN (default ../shared/data/faces/flame/flame_registered_scan.ply),
# FIELDS (default "gof median"). Prints one line per run:
#   size field wall_s cpu_s peak_rss_mb triangles chamfer_l1 accuracy completeness normal_consistency
# The scenes (~62 bytes per Gaussian) and meshes stay in WORK; delete it when done.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
target="${CARGO_TARGET_DIR:-$here/target}"
trisplat="${TRISPLAT:-$target/release/trisplat}"
bench="${TRISPLAT_BENCH:-$target/release/trisplat-bench}"
scan="${SCAN:-$here/../shared/data/faces/flame/flame_registered_scan.ply}"
fields="${FIELDS:-gof median}"
work="${1:?usage: opacity_scale.sh WORK [SIZES...] [-- EXTRA ARGS]}"
shift
sizes=()
while [[ $# -gt 0 && "$1" != "--" ]]; do sizes+=("$1"); shift; done
[[ $# -gt 0 ]] && shift
extra=("$@")
[[ ${#sizes[@]} -eq 0 ]] && sizes=(100000 250000 500000 1000000)
mkdir -p "$work"
echo "size field wall_s cpu_s peak_rss_mb triangles chamfer_l1 accuracy completeness normal_consistency"
for n in "${sizes[@]}"; do
    scene="$work/scene_$n.ply"
    [[ -f "$scene" ]] || "$bench" --no-python gaussian-scene --mesh "$scan" -n "$n" -o "$scene" >&2
    for field in $fields; do
        mesh="$work/mesh_${n}_$field.ply"
        rm -f "$mesh"
        /usr/bin/time -v "$trisplat" --json opacity-mesh "$scene" -o "$mesh" --field "$field" \
            "${extra[@]}" > "$work/run_${n}_$field.json" 2> "$work/time_${n}_$field.txt"
        t="$work/time_${n}_$field.txt"
        wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {n=split($2,a,":"); s=0; for(i=1;i<=n;i++) s=s*60+a[i]; print s}' "$t")
        cpu=$(awk -F': ' '/User time/ {u=$2} /System time/ {s=$2} END {print u+s}' "$t")
        rss=$(awk -F': ' '/Maximum resident/ {print int($2/1024)}' "$t")
        "$trisplat" --json eval "$mesh" "$scan" --surface > "$work/eval_${n}_$field.json"
        python3 - "$work/run_${n}_$field.json" "$work/eval_${n}_$field.json" "$n" "$field" "$wall" "$cpu" "$rss" <<'EOF'
import json, sys
run = json.load(open(sys.argv[1]))
ev = json.load(open(sys.argv[2]))
def find(d, key):
    if isinstance(d, dict):
        if key in d and not isinstance(d[key], (dict, list)):
            return d[key]
        for v in d.values():
            r = find(v, key)
            if r is not None:
                return r
    return None
n, field, wall, cpu, rss = sys.argv[3:8]
print(n, field, wall, cpu, rss, find(run, "triangles"),
      *("%.3e" % find(ev, k) for k in ("chamfer_l1", "accuracy", "completeness")),
      "%.4f" % find(ev, "normal_consistency"))
EOF
    done
done
