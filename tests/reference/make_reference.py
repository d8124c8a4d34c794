#!/usr/bin/env python3
"""Writes every reference fixture under fixtures/data/reference/ with the pinned tools.

Usage (from the repository root, in a virtualenv made from requirements.txt):

    python -m venv venv && venv/bin/pip install -r tests/reference/requirements.txt
    venv/bin/python tests/reference/make_reference.py [AREA ...]

Each area lives in its own script `ref_<area>.py` with a `main()`; with no argument every area
runs except those in SEPARATE_ENVIRONMENTS, which need other pinned packages (gsplat + torch:
`requirements-gsplat.txt`) and are run by hand in their own virtualenv:

    python -m venv venv-gs && venv-gs/bin/pip install -r tests/reference/requirements-gsplat.txt
    venv-gs/bin/python tests/reference/ref_render_gsplat.py

The Rust tests in `tests/tests/` compare trisplat against these files; CI never runs Python.
"""

import importlib
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
REQUIREMENTS = HERE / "requirements.txt"
# Areas whose scripts need a different virtualenv (their own pinned requirements file).
SEPARATE_ENVIRONMENTS = {"render_gsplat"}


def check_pinned_versions():
    """Refuses to run with versions other than the pinned ones (outputs would drift)."""
    from importlib.metadata import version, PackageNotFoundError

    bad = []
    for line in REQUIREMENTS.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        name, want = line.split("==")
        try:
            have = version(name)
        except PackageNotFoundError:
            have = None
        if have != want:
            bad.append(f"{name}: want {want}, have {have}")
    if bad:
        sys.exit("pinned versions differ:\n  " + "\n  ".join(bad))


def main():
    check_pinned_versions()
    sys.path.insert(0, str(HERE))
    every = sorted(p.stem[4:] for p in HERE.glob("ref_*.py"))
    areas = sys.argv[1:] or [a for a in every if a not in SEPARATE_ENVIRONMENTS]
    for area in areas:
        print(f"== {area}", flush=True)
        importlib.import_module(f"ref_{area}").main()


if __name__ == "__main__":
    main()
