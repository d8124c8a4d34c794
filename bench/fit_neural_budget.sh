#!/usr/bin/env bash
# `trisplat fit --appearance mlp` against the SH fit at the same time budget (issue #33,
# neural attributes; docs/benchmarks.md "Neural appearance"). Two targets, as
# bench/fit_budget.sh makes them:
#   cm_*  CesiumMan (bundled) at rest, mesh renders with its base-colour texture;
#   la_*  the LAM head's own appearance: its Gaussians rendered at rest are the target images
#         (their alpha the masks), fitted from `bind`'s initialisation of skin.glb.
# Every run starts from `bind`'s one Gaussian per triangle, trains on 24 views of a sphere rig
# and is scored on 6 held-out views of an orbit at 35°, 128 x 128, 2 threads. `sh` fits the
# whole set (geometry, opacity, SH); `mlp` holds the geometry and fits the hash-grid MLP.
#
#     cargo build --release -p trisplat-cli
#     bash bench/fit_neural_budget.sh LAM_DIR OUT_DIR [SECONDS]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
lam="$(realpath "${1:?LAM avatar folder}")"
out="${2:?output folder}"
budget="${3:-60}"
T="$(realpath "${TRISPLAT:-$root/target/release/trisplat}")"
C="$root/fixtures/data/anim/CesiumMan.glb"
mkdir -p "$out" && cd "$out"

"$T" bind "$C" -o cm_bound.ply -q > /dev/null
"$T" cameras "$C" -o cm_train.json --views 24 --size 128x128
"$T" cameras "$C" -o cm_eval.json --rig orbit --views 6 --elevation 35 --size 128x128
"$T" bind "$lam/skin.glb" -o lam_init.ply -q > /dev/null
"$T" cameras "$lam" -o lam_train.json --views 24 --size 128x128
"$T" cameras "$lam" -o lam_eval.json --rig orbit --views 6 --elevation 35 --size 128x128
rm -rf rest && "$T" deform --avatar "$lam" --animation "$lam/skin.glb" -o rest --format ply -q
for s in train eval; do
    rm -rf "render_$s" "img_$s" && mkdir "img_$s"
    "$T" render rest/frame_000000.ply --cameras "lam_$s.json" -o "render_$s" --outputs rgb,alpha -q
    for f in "render_$s"/*_rgb.png; do
        b="$(basename "$f" _rgb.png)"
        cp "$f" "img_$s/$b.png" && cp "render_$s/${b}_alpha.png" "img_$s/${b}_mask.png"
    done
done

B=(--iterations 100000 --time-budget "$budget" --eval-every 250 --threads 2 --json)
run() {
    local name=$1; shift
    /usr/bin/time -f "%e %U %S %M" -o "$name.time" "$T" fit "$@" "${B[@]}" > "$name.json" 2> "$name.err"
    echo "$name $(cat "$name.time")"
}
cm=(cm_bound.ply --template "$C" --cameras cm_train.json --eval-cameras cm_eval.json --color texture)
la=(lam_init.ply --template "$lam/skin.glb" --cameras lam_train.json --eval-cameras lam_eval.json
    --images img_train --eval-images img_eval)
run cm_sh "${cm[@]}" -o cm_sh.ply
run cm_mlp "${cm[@]}" -o cm_mlp.ply --appearance mlp
run la_sh "${la[@]}" -o la_sh.ply
run la_mlp "${la[@]}" -o la_mlp.ply --appearance mlp

python3 - cm_sh cm_mlp la_sh la_mlp <<'PY'
import json, sys
print("| run | iterations | held-out PSNR / SSIM at 0 | at the end | Gaussians | ms / it "
      "| whole process wall | CPU s (user+sys) | peak RSS |")
print("|---|---:|---|---|---:|---:|---:|---:|---:|")
f = lambda v, p: "—" if v is None else f"{v:.{p}f}"
for name in sys.argv[1:]:
    r = json.load(open(name + ".json"))
    wall, user, sys_, kb = open(name + ".time").read().split()[-4:]
    c0, c = r["checkpoints"][0], r["checkpoints"][-1]
    print(f"| {name} | {r['iterations']:,} | {f(c0['eval_psnr'], 2)} / {f(c0['eval_ssim'], 4)} "
          f"| {f(c['eval_psnr'], 2)} / {f(c['eval_ssim'], 4)} | {r['gaussians']:,} "
          f"| {r['ms_per_iteration']:.1f} | {float(wall):.1f} s "
          f"| {float(user) + float(sys_):.1f} | {int(kb) // 1024} MB |")
PY
