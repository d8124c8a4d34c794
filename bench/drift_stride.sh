#!/usr/bin/env bash
# Issue #31's per-frame drift goal measured at a stride over a whole track: each sampled frame
# of a carried run (`extract --topology adaptive|fixed --targets meshes,...` over the whole
# track) against that frame's own extraction (`--topology per-frame --frames k..k+1`):
# Chamfer-L1 of the carried mesh to the own one (`eval --surface`), and both meshes' render
# consistency against the frame's deformed Gaussians (`deform`, then `eval --gaussians`, the
# same default held-out rig for both).
#
#     bash bench/drift_stride.sh LAM_DIR CARRIED_OUT OUT_DIR BINARY [STRIDE] [METHODS]
#         # CARRIED_OUT: the whole-track run's output folder (its <method>/frame_NNNNNN.ply)
#
# Frames already extracted or deformed in OUT_DIR are kept (a second call only evaluates).
# Writes OUT_DIR/drift.tsv: method, frame, Chamfer-L1 (m), IoU carried, IoU own.
set -euo pipefail
lam="$(realpath "${1:?LAM avatar folder}")"
carried="$(realpath "${2:?carried run output folder}")"
out="${3:?output folder}"
bin="$(realpath "${4:?trisplat binary}")"
stride="${5:-81}"
methods="${6:-tsdf,delaunay,alpha}"
track="$lam/test_expression_1s.json"
frames=$(ls "$carried/${methods%%,*}" | grep -c '^frame_.*\.ply$')
mkdir -p "$out"
out="$(realpath "$out")"
field() { python3 -c "import json,sys; d=json.load(sys.stdin); print(d$1)"; }
printf 'method\tframe\tchamfer_l1_m\tiou_carried\tiou_own\n' > "$out/drift.tsv"
for ((k = 0; k < frames; k += stride)); do
  name=$(printf 'frame_%06d.ply' "$k")
  [ -f "$out/own_$k/${methods##*,}/$name" ] || "$bin" extract --avatar "$lam" --animation "$track" --method "$methods" --topology per-frame \
    --frames "$k..$((k + 1))" -o "$out/own_$k" --force -q --consistency-views 0 \
    --targets meshes 2> >(grep -v '^warning' >&2) > /dev/null
  [ -d "$out/gaussians_$k" ] || "$bin" deform --avatar "$lam" --animation "$track" --frames "$k..$((k + 1))" \
    -o "$out/gaussians_$k" -q 2> >(grep -v '^warning' >&2) > /dev/null
  g=$(ls "$out/gaussians_$k"/*.ply | head -1)
  for m in ${methods//,/ }; do
    c="$carried/$m/$name"
    o="$out/own_$k/$m/$name"
    chamfer=$("$bin" eval "$c" "$o" --surface --json -q | field "['chamfer_l1']")
    iou_c=$("$bin" eval "$c" --gaussians "$g" --json -q | field "['render_consistency']['iou']")
    iou_o=$("$bin" eval "$o" --gaussians "$g" --json -q | field "['render_consistency']['iou']")
    printf '%s\t%d\t%s\t%s\t%s\n' "$m" "$k" "$chamfer" "$iou_c" "$iou_o" | tee -a "$out/drift.tsv"
  done
done
