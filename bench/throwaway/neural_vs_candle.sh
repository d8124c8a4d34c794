#!/usr/bin/env bash
# The neural appearance model's forward+backward, hand-written (splat::neural) against
# candle-core's CPU backend with autograd, on one batch (issue #33: choose the library with
# numbers; docs/benchmarks.md "Neural appearance"). Builds a throwaway crate OUTSIDE the
# workspace (its own target dir), runs it, and deletes it:
#
#     bash bench/throwaway/neural_vs_candle.sh [N=100000] [REPS=5]
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
dir="$(mktemp -d /tmp/nbench.XXXXXX)"
trap 'rm -rf "$dir"' EXIT
mkdir -p "$dir/src"
cp "$root/bench/throwaway/neural_vs_candle.rs" "$dir/src/main.rs"
cat > "$dir/Cargo.toml" <<TOML
[package]
name = "nbench"
version = "0.1.0"
edition = "2024"

[dependencies]
trisplat-splat = { path = "$root/splat" }
trisplat-geometry = { path = "$root/geometry" }
candle-core = "0.9"
rayon = "1.12"
TOML
(cd "$dir" && CARGO_TARGET_DIR="$dir/target" cargo build --release -q)
/usr/bin/time -f "%e s wall, %U+%S s CPU, %M KB peak" "$dir/target/release/nbench" "${1:-100000}" "${2:-5}"
