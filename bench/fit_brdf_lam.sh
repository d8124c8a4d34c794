#!/usr/bin/env bash
# The relightable fit on the LAM avatar's head (issue #33; docs/benchmarks.md "Relightable fit
# on the LAM avatar"): a synthetic-materials version of LAM, rendered under the HDR map and fitted
# back by `trisplat fit --appearance brdf`, scored as HRAvatar's Table 3.
#
#   1. `bind` puts one Gaussian on each triangle of LAM's template (skin.glb);
#      `trisplat-bench brdf-avatar make` flattens them along their triangle's normal and gives
#      them known, smoothly varying albedo, roughness and F0 (pipeline::fit::synthetic_materials:
#      truth.ply, its rest-pose world copy truth_world.ply) and makes the start of the fit
#      (init.ply: rotations turned by 17-57 degrees, grey albedo, roughness 0.9, F0 0.04);
#   2. `render --env MAP` relights truth_world.ply for VIEWS training cameras (a sphere rig) and
#      4 held-out ones (an orbit at 20 degrees), SIZE x SIZE, PNG rgb and mask;
#   3. `fit --appearance brdf --fit-normals` from init.ply, with the map known (--env) and with
#      it estimated from a uniform grey 32 x 16 map (--env-fit), ITERATIONS each, 2 threads,
#      timed as whole processes by /usr/bin/time;
#   4. `trisplat-bench brdf-avatar score`: albedo LMSE, normal-map cosine and per-Gaussian
#      shortest-axis |cos| of the start and both fits on the held-out cameras.
#
#     cargo build --release -p trisplat-cli -p trisplat-bench
#     bash bench/fit_brdf_lam.sh LAM_DIR MAP.hdr OUT_DIR [ITERATIONS] [VIEWS] [SIZE]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
lam="$(realpath "${1:?LAM avatar folder}")"
map="$(realpath "${2:?environment map (.hdr)}")"
out="${3:?output folder}"
iterations="${4:-400}"
views="${5:-12}"
size="${6:-128}"
bin="${CARGO_TARGET_DIR:-$root/target}/release"
T="$(realpath "${TRISPLAT:-$bin/trisplat}")"
B="$(realpath "${TRISPLAT_BENCH:-$bin/trisplat-bench}")"
skin="$lam/skin.glb"
light=(--env-rotation 20 --env-intensity 0.8)
mkdir -p "$out" && cd "$out"

"$T" bind "$skin" -o bound.ply -q > /dev/null
"$B" --no-python brdf-avatar make --template "$skin" bound.ply -o .
"$T" cameras "$skin" -o train.json --views "$views" --size "${size}x${size}"
"$T" cameras "$skin" -o eval.json --rig orbit --views 4 --elevation 20 --size "${size}x${size}"
for s in train eval; do
    rm -rf "render_$s" "img_$s" && mkdir "img_$s"
    "$T" render truth_world.ply --cameras "$s.json" -o "render_$s" --env "$map" "${light[@]}" \
        --outputs rgb,alpha -q
    for f in "render_$s"/*_rgb.png; do
        b="$(basename "$f" _rgb.png)"
        cp "$f" "img_$s/$b.png" && cp "render_$s/${b}_alpha.png" "img_$s/${b}_mask.png"
    done
done

common=(init.ply --template "$skin" --cameras train.json --eval-cameras eval.json
        --images img_train --eval-images img_eval --appearance brdf --fit-normals
        --iterations "$iterations" --eval-every "$iterations" --threads 2 --json)
run() {
    local name=$1; shift
    /usr/bin/time -f "%e %U %S %M" -o "$name.time" "$T" fit "${common[@]}" -o "$name.ply" "$@" \
        > "$name.json" 2> "$name.err"
    echo "$name: wall, user, sys s, peak KB: $(cat "$name.time")"
}
run fit_known --env "$map" "${light[@]}"
run fit_env --env-fit
"$B" --no-python brdf-avatar score --template "$skin" --truth truth.ply --cameras eval.json \
    init.ply fit_known.ply fit_env.ply
python3 - fit_known fit_env <<'PY'
import json, sys
for name in sys.argv[1:]:
    r = json.load(open(name + ".json"))
    c0, c = r["checkpoints"][0], r["checkpoints"][-1]
    print(f"{name}: {r['gaussians']} Gaussians, {r['iterations']} iterations, "
          f"{r['ms_per_iteration']:.1f} ms/it; held-out PSNR {c0['eval_psnr']:.2f} -> "
          f"{c['eval_psnr']:.2f} dB, SSIM {c0['eval_ssim']:.4f} -> {c['eval_ssim']:.4f}")
PY
