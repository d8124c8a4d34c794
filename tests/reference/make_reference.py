#!/usr/bin/env python3
"""Writes every reference fixture under fixtures/data/reference/ with the pinned tools.

Usage (from the repository root, in a virtualenv made from requirements.txt):

    python -m venv venv && venv/bin/pip install -r tests/reference/requirements.txt
    venv/bin/python tests/reference/make_reference.py [AREA ...]

Each area lives in its own script `ref_<area>.py` with a `main()`; with no argument every area
runs. The Rust tests in `tests/tests/` compare trisplat against these files; CI never runs Python.
"""

import importlib
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
REQUIREMENTS = HERE / "requirements.txt"


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
    areas = sys.argv[1:] or sorted(p.stem[4:] for p in HERE.glob("ref_*.py"))
    for area in areas:
        print(f"== {area}", flush=True)
        importlib.import_module(f"ref_{area}").main()


if __name__ == "__main__":
    main()
