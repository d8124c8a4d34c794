#!/usr/bin/env bash
# `trisplat fit` at a fixed time budget, with and without the refine loop and densification
# (issue #14's acceptance; docs/benchmarks.md "Fitting at a fixed time"). Three targets:
#   cm_*  CesiumMan (bundled) at rest, mesh renders with its base-colour texture;
#   lm_*  the LAM head's skin.glb at rest, mesh renders coloured by the normal (it has no
#         texture or vertex colours), scored for depth and normal error too;
#   la_*  the LAM head's own appearance: the LAM Gaussians rendered at rest are the target
#         images (with their alpha as masks), fitted from `bind`'s initialisation of skin.glb.
# Every run starts from `bind`'s one Gaussian per triangle, trains on 24 views of a sphere rig
# and is scored on 6 held-out views of an orbit at 35°, all 128 x 128, 2 threads.
#
#     cargo build --release
#     bash bench/fit_budget.sh LAM_DIR OUT_DIR [SECONDS]     # e.g. ../shared/data/avatars/lam_p2-1
#
# Prints one line per run (whole-process wall seconds and peak KB from /usr/bin/time) and a
# Markdown table of the results from each run's --json.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
lam="$(realpath "${1:?LAM avatar folder}")"
out="${2:?output folder}"
budget="${3:-120}"
T="$(realpath "${TRISPLAT:-$root/target/release/trisplat}")"
C="$root/fixtures/data/anim/CesiumMan.glb"
mkdir -p "$out" && cd "$out"

"$T" bind "$C" -o cm_bound.ply -q > /dev/null
"$T" cameras "$C" -o cm_train.json --views 24 --size 128x128
"$T" cameras "$C" -o cm_eval.json --rig orbit --views 6 --elevation 35 --size 128x128
"$T" bind "$lam/skin.glb" -o lam_init.ply -q > /dev/null
"$T" cameras "$lam" -o lam_train.json --views 24 --size 128x128
"$T" cameras "$lam" -o lam_eval.json --rig orbit --views 6 --elevation 35 --size 128x128
# LAM's appearance as images: its Gaussians at rest (skin.glb's rest state as the animation).
rm -rf rest && "$T" deform --avatar "$lam" --animation "$lam/skin.glb" -o rest --format ply -q
for s in train eval; do
    rm -rf "render_$s" "img_$s" && mkdir "img_$s"
    "$T" render rest/frame_000000.ply --cameras "lam_$s.json" -o "render_$s" --outputs rgb,alpha -q
    for f in "render_$s"/*_rgb.png; do
        b="$(basename "$f" _rgb.png)"
        cp "$f" "img_$s/$b.png" && cp "render_$s/${b}_alpha.png" "img_$s/${b}_mask.png"
    done
done

B=(--iterations 100000 --time-budget "$budget" --eval-every 500 --threads 2 --json)
run() {
    local name=$1; shift
    /usr/bin/time -f "%e %M" -o "$name.time" "$T" fit "$@" "${B[@]}" > "$name.json" 2> "$name.err"
    echo "$name $(cat "$name.time")"
}
cm=(cm_bound.ply --template "$C" --cameras cm_train.json --eval-cameras cm_eval.json --color texture)
lm=(lam_init.ply --template "$lam/skin.glb" --cameras lam_train.json --eval-cameras lam_eval.json)
la=("${lm[@]}" --images img_train --eval-images img_eval)
run cm_none "${cm[@]}" -o cm_none.ply
run cm_refine "${cm[@]}" -o cm_refine.ply --refine-every 500
run cm_dens "${cm[@]}" -o cm_dens.ply --densify
run cm_densref "${cm[@]}" -o cm_densref.ply --densify --refine-every 500
for t in lm la; do
    declare -n args="$t"
    run "${t}_none" "${args[@]}" -o "${t}_none.ply"
    run "${t}_refine" "${args[@]}" -o "${t}_refine.ply" --refine-every 500
    run "${t}_dens" "${args[@]}" -o "${t}_dens.ply" --densify
done

python3 - cm_none cm_refine cm_dens cm_densref lm_none lm_refine lm_dens la_none la_refine la_dens <<'PY'
import json, sys
print("| run | iterations | held-out PSNR / SSIM at 0 | at the end | depth L1 | normal ° "
      "| Gaussians | refines / densify steps | ms / it | whole process | peak RSS |")
print("|---|---:|---|---|---:|---:|---|---|---:|---:|---:|")
f = lambda v, p: "—" if v is None else f"{v:.{p}f}"
for name in sys.argv[1:]:
    r = json.load(open(name + ".json"))
    wall, kb = open(name + ".time").read().split()[-2:]
    c0, c = r["checkpoints"][0], r["checkpoints"][-1]
    print(f"| {name} | {r['iterations']:,} | {f(c0['eval_psnr'], 2)} / {f(c0['eval_ssim'], 4)} "
          f"| {f(c['eval_psnr'], 2)} / {f(c['eval_ssim'], 4)} | {f(c['eval_depth_l1'], 4)} "
          f"| {f(c['eval_normal_deg'], 1)} | {r['before']:,} → {r['gaussians']:,} "
          f"| {len(r['refines'])} / {len(r['densify'])} | {r['ms_per_iteration']:.1f} "
          f"| {float(wall):.1f} s | {int(kb) // 1024} MB |")
PY
