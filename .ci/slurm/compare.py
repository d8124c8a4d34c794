#!/usr/bin/env python3
"""Whether a merged extract run equals one run over the same frames (docs/shards.md).

    compare.py ONE_RUN MERGED [--frames N]

Byte for byte (sha256): every `<method>/frame_NNNNNN.ply` and `<method>.glb` (and glTF
parts) of either folder; the same file names on both sides. report.json: equal after dropping
what legitimately differs between one run and merged shards:
  - timings: `ms`, `median_ms`, `render_ms`, `update_ms`, `deform_ms`;
  - the incremental Delaunay's bookkeeping, since each shard (and a resumed run) starts with a
    rebuild where one run updates: per frame `rebuilt`, `hopped`, `charts_redone`, `searches`,
    and the summaries `rebuilt_frames`, `hopped_fraction`, `charts_redone_fraction`;
  - `thumbnails` (merge keeps the pictures of the shard nearest the middle frame).
With --frames N, both reports must list frames 0..N and no failed frame.
Prints a summary of every difference and exits 1 if there is one; standard library only.
"""

import argparse
import hashlib
import json
import re
import sys
from pathlib import Path

TIMINGS = {"ms", "median_ms", "render_ms", "update_ms", "deform_ms"}
DELAUNAY_BOOKKEEPING = {
    "rebuilt",
    "hopped",
    "charts_redone",
    "searches",
    "rebuilt_frames",
    "hopped_fraction",
    "charts_redone_fraction",
}
IGNORED_TOP = {"thumbnails"}
MESH_FILE = re.compile(r"^(?:[a-z]+/frame_\d{6}\.ply|[a-z]+(?:_part\d+)?\.glb)$")


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def mesh_files(folder):
    """Frame files and animated glTFs of a run folder, by path relative to it."""
    return {
        str(p.relative_to(folder)): p
        for p in sorted(folder.rglob("*"))
        if p.is_file() and MESH_FILE.match(str(p.relative_to(folder)))
    }


def strip(value, top=True):
    """The report without the fields that may differ (see the module docs)."""
    if isinstance(value, dict):
        return {
            k: strip(v, False)
            for k, v in value.items()
            if k not in TIMINGS
            and k not in DELAUNAY_BOOKKEEPING
            and not (top and k in IGNORED_TOP)
        }
    if isinstance(value, list):
        return [strip(v, False) for v in value]
    return value


def differences(a, b, path=""):
    """Paths (JSON pointer-like) where a and b differ, with both values."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in {'merged' if k not in a else 'one run'}")
            else:
                out += differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} entries in one run, {len(b)} merged"]
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, f"{path}/{i}")
        return out
    if a != b:
        return [f"{path}: one run {json.dumps(a)[:80]}, merged {json.dumps(b)[:80]}"]
    return []


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("one_run", type=Path)
    ap.add_argument("merged", type=Path)
    ap.add_argument("--frames", type=int, help="frames both runs must hold: 0..N")
    args = ap.parse_args()

    problems = []
    one, merged = mesh_files(args.one_run), mesh_files(args.merged)
    for name in sorted(set(one) - set(merged)):
        problems.append(f"{name}: missing in the merged folder")
    for name in sorted(set(merged) - set(one)):
        problems.append(f"{name}: in the merged folder, not in one run's")
    common = sorted(set(one) & set(merged))
    differing = [n for n in common if sha256(one[n]) != sha256(merged[n])]
    problems += [f"{n}: bytes differ" for n in differing]
    if not common:
        problems.append("no frame files or glTFs to compare")

    reports, report_diffs = [], None
    for folder in (args.one_run, args.merged):
        try:
            reports.append(json.loads((folder / "report.json").read_text()))
        except (OSError, ValueError) as e:
            problems.append(f"{folder}/report.json: {e}")
    if len(reports) == 2:
        report_diffs = differences(strip(reports[0]), strip(reports[1]))
        problems += [f"report.json{d}" for d in report_diffs]
        if args.frames is not None:
            for folder, r in zip((args.one_run, args.merged), reports):
                if r.get("frames") != list(range(args.frames)):
                    problems.append(f"{folder}/report.json: frames are not 0..{args.frames}")
                if r.get("failed_frames"):
                    problems.append(f"{folder}/report.json: failed frames {r['failed_frames']}")

    print(
        f"compared {len(common)} frame files and glTFs (sha256): {len(differing)} differ; "
        f"report.json without timings, Delaunay bookkeeping and thumbnails: "
        f"{'equal' if report_diffs == [] else 'DIFFERENT'}"
    )
    if problems:
        print(f"merged run != one run, {len(problems)} difference(s):")
        for p in problems[:40]:
            print(f"  {p}")
        if len(problems) > 40:
            print(f"  ... and {len(problems) - 40} more")
        return 1
    print("merged run == one run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
