"""Draws docs/img/lam_frame0_before_after.png: LAM p2-1 frame 0 meshed by each method before and
after issue #12's extraction changes, as normal maps (front and three-quarter views).

Usage (release build; Pillow):

    python docs/img/lam_before_after.py target/release/trisplat ../shared/data/avatars/lam_p2-1 WORK

"Before" is every Gaussian with each splat at its mean's depth (`--min-contribution 0
--tsdf-splat-depth mean`), "after" the defaults (hidden Gaussians left out, ray depth).
"""

import json
import subprocess
import sys
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

METHODS = ["tsdf", "delaunay", "alpha"]
VIEWS = [2, 1]  # of an 8-view orbit at 10° elevation: the front, a three-quarter view
CROP = (40, 10, 280, 310)
RUNS = [
    ("before", "before: every Gaussian, mean depth",
     ["--min-contribution", "0", "--tsdf-splat-depth", "mean"]),
    ("after", "after: the defaults", []),
]


def run(*args):
    subprocess.run([str(a) for a in args], check=True, stdout=subprocess.DEVNULL)


def main():
    trisplat, avatar, work = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    work.mkdir(parents=True, exist_ok=True)
    reports = {}
    for name, _, extra in RUNS:
        out = work / f"lam_{name}"
        run(trisplat, "extract", "--avatar", avatar, "--animation",
            avatar / "test_expression_1s.json", "--frames", "0..1", "--method",
            ",".join(METHODS), "--gt", "gaussians", "--targets", "meshes,report", "-q",
            "--force", "-o", out, *extra)
        reports[name] = json.loads((out / "report.json").read_text())
    cams = work / "cams.json"
    run(trisplat, "cameras", work / "lam_after/tsdf/frame_000000.ply", "--rig", "orbit",
        "--views", 8, "--size", "320x320", "--elevation", 10, "-o", cams)
    for name, _, _ in RUNS:
        for m in METHODS:
            run(trisplat, "render", "--mesh", work / f"lam_{name}/{m}/frame_000000.ply",
                "--cameras", cams, "--outputs", "normal", "-q", "-o", work / f"nm_{name}_{m}")
    cw, ch = CROP[2] - CROP[0], CROP[3] - CROP[1]
    label = 22
    sheet = Image.new("RGB", (cw * 2 * len(METHODS), label + (ch + label) * len(RUNS)))
    draw = ImageDraw.Draw(sheet)
    font_file = Path(__file__).resolve().parents[2] / "pipeline/assets"
    fonts = sorted(font_file.glob("*.ttf"))
    font = ImageFont.truetype(str(fonts[0]), 14) if fonts else ImageFont.load_default()
    for j, m in enumerate(METHODS):
        draw.rectangle([j * 2 * cw, 0, (j + 1) * 2 * cw, label], fill=(255, 255, 255))
        draw.text((j * 2 * cw + 6, 3), m, fill=(0, 0, 0), font=font)
    for r, (name, title, _) in enumerate(RUNS):
        y0 = label + r * (ch + label)
        used = reports[name]["gaussians_used"]
        line = f"{title} (delaunay, alpha: {used['kept']:,} of {used['total']:,} Gaussians) —"
        for m in METHODS:
            mean = reports[name]["methods"][m]["mean"]
            pieces = round(mean["components"])
            line += f"  {m}: Chamfer {mean['chamfer_l1'] * 1000:.2f} mm, {pieces} piece" + (
                "s" if pieces != 1 else "")
        draw.rectangle([0, y0, sheet.width, y0 + label], fill=(230, 230, 230))
        draw.text((6, y0 + 3), line, fill=(0, 0, 0), font=font)
        for j, m in enumerate(METHODS):
            for k, view in enumerate(VIEWS):
                image = Image.open(work / f"nm_{name}_{m}/view_{view:03d}_normal.png")
                sheet.paste(image.convert("RGB").crop(CROP), ((2 * j + k) * cw, y0 + label))
    target = Path(__file__).resolve().parent / "lam_frame0_before_after.png"
    sheet.save(target, optimize=True)
    print(target, sheet.size)


if __name__ == "__main__":
    main()
