#!/usr/bin/env python3
"""Writes a synthetic speckle pair (8-bit PNG): ref.png and def.png of SIZE x SIZE pixels.

The reference is a sum of Gaussian spots (radius about 2 px) at random positions; the deformed
image moves every spot by a known affine field about the image centre (a translation of
(0.35, -0.45) px and a strain of a few 1e-3), so that a DIC of the pair has a known answer.

    python3 speckle.py SIZE OUT_DIR [SEED]
"""

import sys
from pathlib import Path

import numpy as np
from PIL import Image

# The known field: u(X) = SHIFT + GRADIENT (X - c), c the image centre (px; x = column).
SHIFT = (0.35, -0.45)
GRADIENT = ((0.002, 0.001), (-0.0015, 0.0025))


def known_field(x: float, y: float, size: int) -> tuple:
    """The pair's displacement (px) at the reference point (x, y) of a SIZE x SIZE pair."""
    c = size / 2
    (g00, g01), (g10, g11) = GRADIENT
    return (SHIFT[0] + g00 * (x - c) + g01 * (y - c), SHIFT[1] + g10 * (x - c) + g11 * (y - c))


def render(size: int, centres: np.ndarray, amplitude: np.ndarray, sigma: float) -> np.ndarray:
    img = np.zeros((size, size))
    r = int(np.ceil(3 * sigma))
    offsets = np.arange(-r, r + 1)
    ix = np.floor(centres[:, 0]).astype(int)
    iy = np.floor(centres[:, 1]).astype(int)
    for dy in offsets:
        for dx in offsets:
            px, py = ix + dx, iy + dy
            ok = (px >= 0) & (px < size) & (py >= 0) & (py < size)
            d2 = (px - centres[:, 0]) ** 2 + (py - centres[:, 1]) ** 2
            np.add.at(img, (py[ok], px[ok]), (amplitude * np.exp(-d2 / (2 * sigma**2)))[ok])
    return img


def main() -> None:
    size = int(sys.argv[1])
    out = Path(sys.argv[2])
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 2024
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sigma = 1.5
    n = int(size * size / (2.5 * sigma) ** 2)
    centres = rng.uniform(-8, size + 8, (n, 2))
    amplitude = rng.uniform(0.5, 1.0, n)
    c = np.array([size / 2, size / 2])
    g = np.array(GRADIENT)
    moved = centres + np.array(SHIFT) + (centres - c) @ g.T
    ref = render(size, centres, amplitude, sigma)
    dfm = render(size, moved, amplitude, sigma)
    scale = 230.0 / max(ref.max(), dfm.max())
    for name, img in (("ref.png", ref), ("def.png", dfm)):
        grey = np.clip(np.rint(10 + img * scale), 0, 255).astype(np.uint8)
        Image.fromarray(grey, mode="L").save(out / name)


if __name__ == "__main__":
    main()
