"""Composition check of an independent DIC on the shared Logiq E9 frames: scikit-image's
iterative Lucas-Kanade (`optical_flow_ilk`) on 048->050, 050->052 and 048->052, the two steps
composed (u_AC(x) ~ u_AB(x) + u_BC(x + u_AB(x))) and compared with the direct one over the ROI
144,80,512x416 on points every 8 px. The same check as `femu dic-check`'s composition, to tell
what belongs to the frames (speckle decorrelation) from what belongs to femu-dic (README, DIC on
real scanner frames).

Usage: python lk_composition.py DIR  (DIR holds gastroc_jumping_048.png ... _052.png)
"""
import sys

import numpy as np
from PIL import Image
from scipy.ndimage import gaussian_filter, map_coordinates
from skimage.registration import optical_flow_ilk


def grey(p):
    im = np.asarray(Image.open(p).convert("RGB"), dtype=np.float64)
    return 0.299 * im[..., 0] + 0.587 * im[..., 1] + 0.114 * im[..., 2]


frames = {k: grey(f"{sys.argv[1]}/gastroc_jumping_{k}.png") for k in ("048", "050", "052")}
x0, y0, x1, y1 = 144, 80, 656, 496
yy, xx = np.mgrid[y0:y1:8, x0:x1:8].astype(float)


def at(field, x, y):
    return map_coordinates(field, [y, x], order=1, mode="nearest")


for radius in (7, 15):
    for smooth in (0, 4):
        flows = {}
        for a, b in (("048", "050"), ("050", "052"), ("048", "052")):
            v, u = optical_flow_ilk(frames[a], frames[b], radius=radius)
            if smooth:
                u, v = gaussian_filter(u, smooth), gaussian_filter(v, smooth)
            flows[a + b] = (u, v)
        uab, vab = (at(c, xx, yy) for c in flows["048050"])
        ubc, vbc = (at(c, xx + uab, yy + vab) for c in flows["050052"])
        uac, vac = (at(c, xx, yy) for c in flows["048052"])
        ex, ey = uab + ubc - uac, vab + vbc - vac
        print(
            f"radius {radius} px, smoothing {smooth} px: composition RMS "
            f"({np.sqrt(np.mean(ex**2)):.2f}, {np.sqrt(np.mean(ey**2)):.2f}) px, "
            f"mean motion 048->052 ({uac.mean():.2f}, {vac.mean():.2f}) px"
        )
