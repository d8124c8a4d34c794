#!/usr/bin/env bash
# Per target: executions and run time summed over its instances, corpus size, crashes, hangs.
cd "$(dirname "$0")"
printf '%-16s %12s %9s %8s %8s %6s\n' target execs run_s corpus crashes hangs
for d in out/*/; do
    t=$(basename "$d")
    execs=0; run=0; corpus=0; crashes=0; hangs=0
    for s in "$d"*/fuzzer_stats; do
        [ -f "$s" ] || continue
        v() { awk -F' *: *' -v k="$1" '$1==k {print $2}' "$s"; }
        execs=$((execs + $(v execs_done))); run=$((run + $(v run_time)))
        c=$(v corpus_count); [ "$c" -gt "$corpus" ] && corpus=$c
        crashes=$((crashes + $(v saved_crashes))); hangs=$((hangs + $(v saved_hangs)))
    done
    printf '%-16s %12d %9d %8d %8d %6d\n' "$t" "$execs" "$run" "$corpus" "$crashes" "$hangs"
done
