#!/usr/bin/env bash
# The LAM avatar checked end to end between two builds (issue #35's "same outputs", #32's
# shard regression): frames 0, 450 and 900 of its 973-frame ARKit track meshed by tsdf,
# delaunay and alpha with each binary (whole-process seconds and peak KB from /usr/bin/time),
# each mesh's render consistency against the avatar's own Gaussians from 16 held-out views
# (bench/python/render_consistency.py), and frames 0..16 as one run against shards 0..8 and
# 8..16 merged (frame files and animated glTFs compared byte for byte).
#
#     cargo build --release
#     bash bench/lam_check.sh LAM_DIR OUT_DIR BASE_BINARY [NEW_BINARY]
#         # LAM_DIR e.g. ../shared/data/avatars/lam_p2-1; NEW_BINARY: target/release/trisplat
#
# Needs numpy for the consistency step.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
lam="$(realpath "${1:?LAM avatar folder}")"
out="${2:?output folder}"
base="$(realpath "${3:?baseline trisplat binary}")"
new="$(realpath "${4:-$root/target/release/trisplat}")"
track="$lam/test_expression_1s.json"
mkdir -p "$out" && cd "$out"
binary() { if [ "$1" = base ]; then echo "$base"; else echo "$new"; fi; }
for b in base new; do
  for f in 0 450 900; do
    /usr/bin/time -f "$b frame $f: %e s, %M KB" "$(binary $b)" extract --avatar "$lam" \
      --animation "$track" --method tsdf,delaunay,alpha --frames "$f" -o "$b/f$f" --force -q \
      > /dev/null 2> >(grep -v '^warning' >&2)
  done
done
for f in 0 450 900; do
  "$new" deform --avatar "$lam" --animation "$track" --frames "$f" -o "g$f" -q > /dev/null 2>&1
done
python3 "$root/bench/python/render_consistency.py" "$new" .
for b in base new; do
  t="$(binary $b)"
  for range in 0..16 0..8 8..16; do
    "$t" extract --avatar "$lam" --animation "$track" --method delaunay,alpha --frames "$range" \
      -o "sh_$b/$range" --force -q > /dev/null 2>&1
  done
  if "$t" merge "sh_$b/0..8" "sh_$b/8..16" -o "sh_$b/merged" --force -q > /dev/null 2> "sh_$b/merge.err"; then
    differ=0; files=0
    for file in sh_$b/0..16/{delaunay,alpha}/frame_*.ply sh_$b/0..16/{delaunay,alpha}.glb; do
      files=$((files + 1))
      cmp -s "$file" "sh_$b/merged/${file#sh_$b/0..16/}" || differ=$((differ + 1))
    done
    echo "$b: $differ of $files frame files and glTFs differ between one run and the merged shards"
  else
    echo "$b: merge refused: $(cat "sh_$b/merge.err")"
  fi
done
