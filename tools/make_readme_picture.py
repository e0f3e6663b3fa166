"""Render the README's picture, ``docs/_static/varflow.png``, from varflow's generators.

Objects moving up to 77 px over a photograph (``make_large_pair("objects", seed=100)``):
the first frame, the true flow and the flows of ``tvl1`` and ``tvl1-ld`` in the
Middlebury colour coding, each with its mean endpoint error.  No benchmark data needed::

    python tools/make_readme_picture.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import varflow
from varflow.generators.large_pairs import make_large_pair

OUT = Path(__file__).resolve().parents[1] / "docs" / "_static" / "varflow.png"


def main() -> None:
    pair = make_large_pair("objects", seed=100, shape=(240, 320))
    gt = np.where(pair.valid[..., None], pair.flow, np.nan).astype(np.float32)
    radius = float(np.nanmax(np.hypot(gt[..., 0], gt[..., 1])))
    tiles = [((pair.frame0 * 255).round().astype(np.uint8), "frame 0"),
             (varflow.flow_to_color(gt, max_radius=radius), "true flow")]
    for method in ("tvl1", "tvl1-ld"):
        flow = varflow.flow(pair.frame0, pair.frame1, method)
        aee = varflow.evaluate(flow, gt)["aee"]
        tiles.append((varflow.flow_to_color(flow, max_radius=radius),
                      f"{method}: AEE {aee:.2f} px"))
    h, w = tiles[0][0].shape[:2]
    gap, band = 6, 22
    canvas = Image.new("RGB", (len(tiles) * w + (len(tiles) - 1) * gap, h + band), "white")
    draw = ImageDraw.Draw(canvas)
    for k, (img, caption) in enumerate(tiles):
        x = k * (w + gap)
        canvas.paste(Image.fromarray(img), (x, band))
        draw.text((x + 4, 4), caption, fill=(0, 0, 0))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(OUT, optimize=True)
    print(f"wrote {OUT} ({canvas.size[0]}x{canvas.size[1]})")


if __name__ == "__main__":
    main()
