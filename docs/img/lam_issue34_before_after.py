"""Draws docs/img/lam_issue34_before_after.png: LAM p2-1 frame 0, the avatar's own Gaussians
beside each method's mesh before and after issue #34 ("Meshes that show what the avatar
shows"), as normal maps from a front and a three-quarter view that the extraction did not use.

Usage (two release builds of `trisplat`, Pillow):

    python docs/img/lam_issue34_before_after.py BEFORE/trisplat AFTER/trisplat \
        ../shared/data/avatars/lam_p2-1 WORK

BEFORE is a build of the commit before the issue's first change (20c9306~1); AFTER the
current one. Both run `extract` with their defaults on frame 0; every mesh is then scored by
AFTER's `eval --gaussians` (silhouette IoU and depth error against the Gaussians from 16
held-out views), so the numbers on the sheet come from one rule. The opacity method did not
exist before the issue: its "before" cell is left empty.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

METHODS = ["tsdf", "delaunay", "alpha", "opacity"]
VIEWS = [2, 1]  # of an 8-view orbit at 10° elevation: the front, a three-quarter view
CROP = (40, 10, 280, 310)
LABEL = 22


def run(*args, capture=False):
    result = subprocess.run([str(a) for a in args], check=True,
                            stdout=subprocess.PIPE if capture else subprocess.DEVNULL)
    return result.stdout


def extract(trisplat, avatar, out, methods):
    run(trisplat, "extract", "--avatar", avatar, "--animation",
        avatar / "test_expression_1s.json", "--frames", "0..1", "--method", ",".join(methods),
        "--targets", "meshes,report", "-q", "--force", "-o", out)


def consistency(trisplat, mesh, gaussians):
    """AFTER's render consistency of `mesh` against the frame's Gaussians."""
    out = json.loads(run(trisplat, "--json", "eval", mesh, "--gaussians", gaussians,
                         capture=True))
    found = {}

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key in ("iou", "render_iou", "depth_error_median", "median_depth_error"):
                    found.setdefault(key, value)
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(out)
    iou = found.get("iou", found.get("render_iou"))
    median = found.get("depth_error_median", found.get("median_depth_error"))
    return iou, median


def main():
    before, after = Path(sys.argv[1]), Path(sys.argv[2])
    avatar, work = Path(sys.argv[3]), Path(sys.argv[4])
    work.mkdir(parents=True, exist_ok=True)
    extract(before, avatar, work / "before", METHODS[:3])
    extract(after, avatar, work / "after", METHODS)
    gaussians = work / "g0"
    shutil.rmtree(gaussians, ignore_errors=True)
    run(after, "deform", "--avatar", avatar, "--animation", avatar / "test_expression_1s.json",
        "--frames", "0..1", "-o", gaussians)
    splats = sorted(gaussians.glob("*.ply"))[0]
    cams = work / "cams.json"
    run(after, "cameras", work / "after/tsdf/frame_000000.ply", "--rig", "orbit", "--views", 8,
        "--size", "320x320", "--elevation", 10, "-o", cams)
    run(after, "render", splats, "--cameras", cams, "--outputs", "rgb,normal", "-q",
        "-o", work / "splats")
    cells = {}
    for name in ("before", "after"):
        for m in METHODS:
            mesh = work / name / m / "frame_000000.ply"
            if not mesh.exists():
                continue
            run(after, "render", "--mesh", mesh, "--cameras", cams, "--outputs", "normal", "-q",
                "-o", work / f"nm_{name}_{m}")
            cells[(name, m)] = consistency(after, mesh, splats)

    cw, ch = CROP[2] - CROP[0], CROP[3] - CROP[1]
    columns = ["the Gaussians"] + METHODS
    sheet = Image.new("RGB", (cw * 2 * len(columns), LABEL + 2 * (ch + LABEL)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    fonts = sorted((Path(__file__).resolve().parents[2] / "pipeline/assets").glob("*.ttf"))
    font = ImageFont.truetype(str(fonts[0]), 14) if fonts else ImageFont.load_default()
    for j, title in enumerate(columns):
        draw.text((j * 2 * cw + 6, 3), title, fill=(0, 0, 0), font=font)
    for r, name in enumerate(("before", "after")):
        y0 = LABEL + r * (ch + LABEL)
        draw.rectangle([0, y0, sheet.width, y0 + LABEL], fill=(230, 230, 230))
        splat_output = "rgb" if r == 0 else "normal"
        draw.text((6, y0 + 3), f"{name}   (Gaussians: {splat_output})", fill=(0, 0, 0), font=font)
        for k, view in enumerate(VIEWS):
            image = Image.open(work / f"splats/view_{view:03d}_{splat_output}.png")
            sheet.paste(image.convert("RGB").crop(CROP), (k * cw, y0 + LABEL))
        for j, m in enumerate(METHODS, start=1):
            if (name, m) not in cells:
                draw.text((j * 2 * cw + 6, y0 + LABEL + ch // 2), "(no such method)",
                          fill=(120, 120, 120), font=font)
                continue
            iou, median = cells[(name, m)]
            draw.text((j * 2 * cw + 6, y0 + 3),
                      f"{m}: IoU {iou:.3f}, median {median * 1000:.1f} mm",
                      fill=(0, 0, 0), font=font)
            for k, view in enumerate(VIEWS):
                image = Image.open(work / f"nm_{name}_{m}/view_{view:03d}_normal.png")
                sheet.paste(image.convert("RGB").crop(CROP), ((2 * j + k) * cw, y0 + LABEL))
    target = Path(__file__).resolve().parent / "lam_issue34_before_after.png"
    sheet.quantize(256).save(target, optimize=True)  # a palette: a third of the bytes
    print(target, sheet.size)
    for key, value in sorted(cells.items()):
        print(key, value)


if __name__ == "__main__":
    main()
