#!/usr/bin/env python3
"""A contact sheet of labelled crops (`vpcal label` or `vpcal synth crops`), to look at the labels.

Each tile is one crop with its detector box (white), a line from the box centre towards its
VP1 label (green) and towards its VP2 label (red), and the label weights printed under it.
Lines are drawn as far as the tile reaches; a VP far outside still gives its direction.

Usage: scripts/label_sheet.py DIR OUT.png [--count 48] [--camera NAME] [--seed 1]
Needs Pillow (pip install pillow).
"""
import argparse
import json
import os
import random

from PIL import Image, ImageDraw

TILE = 160


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=48)
    ap.add_argument("--camera")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    with open(os.path.join(a.dir, "samples.jsonl")) as f:
        recs = [json.loads(line) for line in f if line.strip()]
    if a.camera:
        recs = [r for r in recs if r.get("meta", {}).get("camera") == a.camera]
    random.Random(a.seed).shuffle(recs)
    recs = recs[: a.count]
    cols = 8
    rows = max(1, (len(recs) + cols - 1) // cols)
    sheet = Image.new("RGB", (cols * TILE, rows * (TILE + 14)), (30, 30, 30))
    for k, r in enumerate(recs):
        img = Image.open(os.path.join(a.dir, r["image"])).convert("RGB")
        s = TILE / max(img.width, img.height)
        img = img.resize((max(1, round(img.width * s)), max(1, round(img.height * s))))
        d = ImageDraw.Draw(img)
        x0, y0, x1, y1 = (v * s for v in r["box2d"])
        d.rectangle([x0, y0, x1, y1], outline=(255, 255, 255))
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        for key, colour in (("vp1", (0, 255, 0)), ("vp2", (255, 0, 0))):
            vx, vy = r[key][0] * s, r[key][1] * s
            dx, dy = vx - cx, vy - cy
            n = (dx * dx + dy * dy) ** 0.5 or 1.0
            reach = min(n, 2 * TILE)
            d.line([cx, cy, cx + dx / n * reach, cy + dy / n * reach], fill=colour, width=2)
        tx, ty = (k % cols) * TILE, (k // cols) * (TILE + 14)
        sheet.paste(img, (tx, ty))
        w = r.get("label_weight", [1.0, 1.0])
        cam = r.get("meta", {}).get("camera", r.get("meta", {}).get("scene", ""))
        ImageDraw.Draw(sheet).text((tx + 2, ty + TILE), f"{cam[:14]} w {w[0]:.2f}/{w[1]:.2f}", fill=(220, 220, 220))
    sheet.save(a.out)
    print(f"{len(recs)} crops -> {a.out}")


if __name__ == "__main__":
    main()
