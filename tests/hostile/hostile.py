#!/usr/bin/env python3
"""The hostile suite of issue #15: every subcommand on broken, oversized, non-finite, deep and
degenerate inputs, run concurrently into one folder and interrupted, with the outcome of each
case classified.

A case passes when the process ends within the timeout with exit code 0 (the input was still
valid), 1 (one `error:` line on stderr naming the file at fault) or 2 (usage), leaves no
`.trisplat-*.tmp` file, and on failure writes no output file. It fails as a panic (exit 101 or
"panicked" on stderr), an abort (killed by a signal: SIGABRT, SIGSEGV, out of memory), a hang
(timeout), a partial file (a temporary or an output left by a failed run), or an error that does
not name the file it was given.

    cargo build --release
    python3 tests/hostile/hostile.py [--trisplat target/release/trisplat] [--cases 40] \
        [--seed 15] [--timeout 30] [--json summary.json]

Standard library only (Python 3.9+). Exit code 1 when any case fails. Takes a few minutes on
two cores at the default size.
"""

import argparse
import collections
import json
import os
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "fixtures" / "data"

# Inputs the mutations start from: (kind, fixture).
SEEDS = {
    "obj": DATA / "spot_triangulated.obj",
    "ply_mesh": DATA / "spot_taubin.ply",
    "ply_ascii": DATA / "io" / "quad_uchar_int_ascii.ply",
    "ply_gaussians": DATA / "render" / "random_deg3.ply",
    "glb": DATA / "anim" / "RiggedFigure.glb",
    "gltf": DATA / "gltf" / "SimpleSkin.gltf",
    "cameras": DATA / "render" / "random_cameras.json",
    "expression": DATA / "lam_mini" / "expression.json",
}


def mutations(data, rng, n):
    """`n` hostile variants of the bytes `data` (seeded): truncations, byte flips, inserted
    junk, numbers replaced by NaN / inf / huge / huge counts, duplicated spans."""
    out = [b"", data[:1], data[: len(data) // 2]]
    words = [b"nan", b"NaN", b"inf", b"-inf", b"1e309", b"-0", b"4294967295",
             b"18446744073709551615", b"-1", b"99999999999", b"1e-320", b"[[[[[[", b"\x00"]
    while len(out) < n:
        r = rng.random()
        d = bytearray(data)
        if r < 0.2:
            d = d[: rng.randrange(1, max(2, len(d)))]
        elif r < 0.45:
            for _ in range(rng.choice([1, 4, 32])):
                if d:
                    d[rng.randrange(len(d))] = rng.randrange(256)
        elif r < 0.7:
            # Replace a number-looking token in the first 4 KB (headers, counts, JSON).
            head = bytes(d[:4096])
            digits = [i for i, c in enumerate(head) if chr(c).isdigit()]
            if digits:
                i = rng.choice(digits)
                j = i
                while j < len(head) and (chr(head[j]).isdigit() or head[j] in b".e-+"):
                    j += 1
                d[i:j] = rng.choice(words)
        elif r < 0.85:
            i = rng.randrange(len(d) + 1)
            d[i:i] = rng.choice(words) * rng.choice([1, 2, 64])
        else:
            i = rng.randrange(len(d) + 1)
            j = min(len(d), i + rng.randrange(1, 256))
            d[i:i] = d[i:j] * rng.choice([2, 100])
        out.append(bytes(d))
    return out[:n]


def structural(kind):
    """Hand-made hostile inputs per kind: the shapes of the defects issue #15 found."""
    cases = []
    if kind in ("ply_mesh", "ply_ascii", "ply_gaussians"):
        cases += [
            b"ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\n"
            b"property float x\nproperty float y\nproperty float z\nend_header\n",
            b"ply\nformat ascii 1.0\nelement junk 4000000000\nend_header\n",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            b"end_header\nnan 0 0\n0 inf 0\n0 0 1\n3 0 1 2\n",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uint float x\nend_header\n"
            b"4294967295 1\n",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
            b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
            b"0 0 0 nan 0 0\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n",
        ]
    if kind == "obj":
        cases += [
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3\n",
            b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            b"v 0 0 0\n" * 3 + b"f 1 1 1\n" * 1000,
            b"v 1e308 1e308 1e308\nv -1e308 -1e308 -1e308\nv 0 1e308 0\nf 1 2 3\n",
        ]
    if kind in ("gltf", "glb"):
        deep = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "scene": 0,
                "nodes": [{"children": [i + 1]} for i in range(20000)] + [{}]}
        cases += [
            json.dumps(deep).encode(),
            b'{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":'
            b'{"POSITION":7}}]}],"nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]}',
            b'{"asset":{"version":"2.0"},"animations":[{"channels":[{"sampler":0,"target":'
            b'{"node":99,"path":"rotation"}}],"samplers":[{"input":0,"output":0}]}]}',
            b"glTF\x02\x00\x00\x00\xff\xff\xff\xff",
            b"[" * 100000,
        ]
    if kind in ("cameras", "expression"):
        cases += [b"[" * 100000, b"{}", b"[]", b'[{"width": 1e308, "height": -1}]',
                  b'{"names": ["a"], "frames": [{"weights": [NaN]}]}']
    return cases


def commands(kind, path, fixtures, out):
    """The commands that read a `kind` file at `path`, writing into `out`."""
    spot, cams, bound, world = (fixtures[k] for k in ("spot", "cams", "bound", "world"))
    o = str(out)
    if kind in ("obj", "ply_mesh", "ply_ascii", "gltf", "glb"):
        ext = ".ply"
        cmds = [
            ["eval", path, spot, "--samples", "500"],
            ["eval", spot, path, "--samples", "500", "--surface"],
            ["convert", path, o + "/c" + ext],
            ["convert", path, o + "/c.glb"],
            ["sample", path, "-n", "500", "-o", o + "/s.ply"],
            ["smooth", path, "-o", o + "/m.ply"],
            ["bind", path, "-o", o + "/b.ply"],
            ["cameras", path, "-o", o + "/cams.json", "--views", "2", "--size", "16x16"],
            ["render", "--mesh", path, "--cameras", cams, "-o", o + "/r"],
            ["alpha-shape", path, "--alpha", "0.1", "-o", o + "/a.ply"],
            ["refine", bound, "--template", path, "-o", o + "/rf.ply"],
            ["fit", bound, "--template", path, "--cameras", cams, "-o", o + "/fit.ply",
             "--iterations", "2"],
            ["extract", "--template", path, "--method", "alpha,delaunay", "-q", "-o", o + "/x"],
        ]
        if kind in ("gltf", "glb"):
            cmds.append(["extract", "--template", path, "--animation", path, "--method",
                         "delaunay", "--frames", "0..2", "-q", "-o", o + "/y"])
        return cmds
    if kind == "ply_gaussians":
        return [
            ["render", path, "--cameras", cams, "-o", o + "/r", "--outputs", "alpha"],
            ["tsdf", "--gaussians", path, "--cameras", cams, "-o", o + "/t.ply"],
            ["densify", path, "-o", o + "/d.ply"],
            ["prune", path, "-o", o + "/p.ply", "--min-opacity", "0.5"],
            ["densify", path, "-o", o + "/ds.ply", "--gate", "seed"],
            ["prune", path, "-o", o + "/ps.ply", "--gate", "seed"],
            ["refine", path, "--template", spot, "-o", o + "/rf.ply"],
            ["fit", path, "--template", spot, "--cameras", cams, "-o", o + "/fit.ply",
             "--iterations", "2"],
            ["bind", spot, "--gaussians", path, "-o", o + "/b.ply"],
            ["deform", "--template", spot, "--gaussians", path, "--animation", spot,
             "-o", o + "/f"],
        ]
    if kind == "cameras":
        return [
            ["render", world, "--cameras", path, "-o", o + "/r", "--outputs", "depth"],
            ["tsdf", "--gaussians", world, "--cameras", path, "-o", o + "/t.ply"],
            ["init", "--cameras", path, "--masks", fixtures["masks"], "-o", o + "/i.ply",
             "-n", "500", "--resolution", "16"],
            ["fit", bound, "--template", spot, "--cameras", path, "-o", o + "/fit.ply",
             "--iterations", "2"],
        ]
    if kind == "expression":
        return [["extract", "--avatar", fixtures["lam"], "--animation", path, "--method",
                 "alpha", "--frames", "0..2", "-q", "-o", o + "/x"]]
    raise ValueError(kind)


def outputs_of(cmd):
    """Output paths a command names (after -o)."""
    return [cmd[i + 1] for i, a in enumerate(cmd) if a == "-o" and i + 1 < len(cmd)]


def run_case(binary, cmd, timeout, file_name):
    """Runs one case and returns its verdict: ok | error | usage, or a failure kind."""
    for o in outputs_of(cmd):
        p = pathlib.Path(o)
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    try:
        res = subprocess.run([binary] + cmd, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "hang", ""
    err = res.stderr.decode(errors="replace")
    if res.returncode == 101 or "panicked" in err:
        return "panic", err[-500:]
    if res.returncode < 0 or res.returncode in (134, 137, 139):
        return "abort", f"signal/exit {res.returncode}: {err[-300:]}"
    outs = [pathlib.Path(o) for o in outputs_of(cmd)]
    for o in outs:
        folder = o if o.is_dir() else o.parent
        if folder.exists() and any(f.name.startswith(".trisplat-") for f in folder.iterdir()):
            return "partial", f"temporary file left in {folder}"
    if res.returncode == 0:
        return "ok", ""
    if res.returncode == 2:
        return "usage", ""
    if res.returncode == 1:
        # Single-file outputs must not exist after a failure (folders may hold what a
        # multi-file command completed: `extract` keeps finished frames for --resume).
        for o in outs:
            if o.suffix and o.is_file():
                return "partial", f"{o} written by a failed run"
        lines = [line for line in err.splitlines() if line.startswith("error:")]
        if len(lines) != 1:
            return "bad-error", err[-500:]
        if file_name not in lines[0]:
            return "unnamed", lines[0][:300]
        return "error", ""
    return "other-exit", f"{res.returncode}: {err[-300:]}"


def concurrency_and_interrupts(binary, fixtures, work, timeout):
    """Two runs into one folder (the second is refused), and interrupted runs (exit 130, no
    temporary files). Returns verdicts."""
    verdicts = []
    cesium = str(DATA / "anim" / "CesiumMan.glb")
    args = ["extract", "--template", cesium, "--animation", cesium, "--method", "tsdf,alpha",
            "-q", "-o", str(work / "busy")]
    for _ in range(3):
        shutil.rmtree(work / "busy", ignore_errors=True)
        first = subprocess.Popen([binary] + args, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.PIPE)
        # Wait for the first run to take the folder's lock (it makes the lock file then).
        deadline = time.time() + timeout
        while not (work / "busy" / ".trisplat.lock").exists() and time.time() < deadline:
            time.sleep(0.05)
        time.sleep(0.2)
        second = subprocess.run([binary] + args, capture_output=True, timeout=timeout)
        err = second.stderr.decode(errors="replace")
        refused = (
            second.returncode == 1
            and "another trisplat run" in err
            and first.poll() is None
        )
        first.send_signal(signal.SIGINT)
        try:
            code = first.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            first.kill()
            verdicts.append(("concurrent", "hang", ""))
            continue
        tmp = [f for f in (work / "busy").rglob(".trisplat-*")] if (work / "busy").exists() else []
        if not refused:
            verdicts.append(("concurrent", "not-refused", err[-300:]))
        elif code != 130:
            verdicts.append(("interrupt", "other-exit", str(code)))
        elif tmp:
            verdicts.append(("interrupt", "partial", str(tmp[0])))
        else:
            verdicts.append(("concurrent+interrupt", "ok", ""))
    return verdicts


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trisplat", default=str(ROOT / "target" / "release" / "trisplat"))
    ap.add_argument("--cases", type=int, default=40, help="mutations per input kind")
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--json", help="write the summary here")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    work = pathlib.Path(tempfile.mkdtemp(prefix="hostile-"))
    started = time.time()
    try:
        fixtures = {
            "spot": str(DATA / "spot_triangulated.obj"),
            "cams": str(DATA / "render" / "random_cameras.json"),
            "world": str(DATA / "render" / "random_deg3.ply"),
            "lam": str(DATA / "lam_mini"),
        }
        bound = work / "bound.ply"
        subprocess.run([args.trisplat, "bind", fixtures["spot"], "-o", str(bound)], check=True,
                       capture_output=True)
        fixtures["bound"] = str(bound)
        # Masks of the fixture cameras for `init`: the world Gaussians' rendered alpha.
        masks = work / "masks"
        subprocess.run([args.trisplat, "render", fixtures["world"], "--cameras",
                        fixtures["cams"], "-o", str(masks), "--outputs", "alpha", "-q"],
                       check=True, capture_output=True)
        fixtures["masks"] = str(masks)
        counts = collections.Counter()
        failures = []
        for kind, seed in SEEDS.items():
            data = seed.read_bytes()
            variants = structural(kind) + mutations(data, rng, args.cases)
            suffix = seed.suffix
            for k, variant in enumerate(variants):
                case_dir = work / f"{kind}_{k}"
                case_dir.mkdir()
                name = f"hostile_{kind}_{k}{suffix}"
                path = case_dir / name
                path.write_bytes(variant)
                out = case_dir / "out"
                out.mkdir()
                for cmd in commands(kind, str(path), fixtures, out):
                    verdict, detail = run_case(args.trisplat, cmd, args.timeout, name)
                    counts[verdict] += 1
                    if verdict not in ("ok", "error", "usage"):
                        failures.append({"kind": kind, "case": k, "command": cmd[0],
                                         "verdict": verdict, "detail": detail,
                                         "input": str(path)})
                shutil.rmtree(out, ignore_errors=True)
                if not any(f["input"] == str(path) for f in failures):
                    shutil.rmtree(case_dir, ignore_errors=True)
        for what, verdict, detail in concurrency_and_interrupts(args.trisplat, fixtures, work,
                                                                 args.timeout):
            counts[verdict] += 1
            if verdict != "ok":
                failures.append({"kind": what, "verdict": verdict, "detail": detail})
        summary = {"cases": sum(counts.values()), "counts": dict(counts),
                   "failures": failures, "seconds": round(time.time() - started, 1),
                   "seed": args.seed, "mutations_per_kind": args.cases}
        print(json.dumps({k: v for k, v in summary.items() if k != "failures"}, indent=1))
        for f in failures[:30]:
            print("FAIL", json.dumps(f)[:400])
        if args.json:
            pathlib.Path(args.json).write_text(json.dumps(summary, indent=1))
        return 1 if failures else 0
    finally:
        if not os.environ.get("HOSTILE_KEEP"):
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
