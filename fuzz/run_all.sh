#!/usr/bin/env bash
# Runs each AFL target in turn for SECONDS (default 300) on two cores (a main and a secondary
# instance sharing fuzz/out/<target>), then prints `cargo afl whatsup -s` for it.
# Usage: fuzz/run_all.sh [SECONDS] [TARGET...]   (build first: cd fuzz && cargo afl build --release)
set -euo pipefail
cd "$(dirname "$0")"
secs=${1:-300}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(ply_mesh ply_gaussians obj gltf gltf_animated cameras_json expression_json npy spz gltf_splats)
fi
export AFL_NO_UI=1 AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1
for t in "${targets[@]}"; do
    mkdir -p out
    # A corpus already fuzzed is resumed rather than restarted.
    input=corpus/$t
    if [ -d "out/$t/main/queue" ]; then input=-; fi
    cargo afl fuzz -V "$secs" -i "$input" -o "out/$t" -M main -m 4096 -t 2000 "target/release/$t" \
        > "out/$t.main.log" 2>&1 &
    main=$!
    sleep 2
    cargo afl fuzz -V "$secs" -i "$input" -o "out/$t" -S sec -m 4096 -t 2000 "target/release/$t" \
        > "out/$t.sec.log" 2>&1 &
    sec=$!
    wait "$main" "$sec" || true
    cargo afl whatsup -s "out/$t" || true
done
