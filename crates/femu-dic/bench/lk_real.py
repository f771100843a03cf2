"""Lucas-Kanade optical flow (scikit-image's `optical_flow_ilk`: iterative Lucas-Kanade over a
Gaussian window, coarse-to-fine) on one image pair, as an independent second opinion on
femu-dic's field (`tests/second_opinion.rs`, `examples/compare_mudic.rs --method lk`).

Usage: python lk_real.py REF.png DEF.png RADIUS SIGMA X0,Y0,X1,Y1 NODES.json OUT.json
NODES.json: {"x": [...], "y": [...]} pixel positions (x = column, y = row, pixel centres at
integers). Grey levels: BT.601 luminance of RGB, as femu-dic reads them. Writes to OUT.json the
flow interpolated at the nodes (bilinear; x = column, y = row, pixels) as `ux`, `uy`, the same
flow smoothed by a Gaussian of standard deviation SIGMA px inside the rectangle
X0..X1 x Y0..Y1 (the DIC's ROI) as `ux_smooth`, `uy_smooth`, and the wall time.
"""
import json
import sys
import time

import numpy as np
from PIL import Image
from scipy.ndimage import gaussian_filter, map_coordinates
from skimage.registration import optical_flow_ilk

ref, de, radius, sigma, rect, nodes_path, out = sys.argv[1:8]
x0, y0, x1, y1 = (int(v) for v in rect.split(","))


def grey(p):
    im = np.asarray(Image.open(p).convert("RGB"), dtype=np.float64)
    return 0.299 * im[..., 0] + 0.587 * im[..., 1] + 0.114 * im[..., 2]


f, g = grey(ref), grey(de)
nodes = json.load(open(nodes_path))
x, y = np.asarray(nodes["x"], dtype=float), np.asarray(nodes["y"], dtype=float)
t0 = time.perf_counter()
# optical_flow_ilk returns (row, column) components: v (down), u (right).
v, u = optical_flow_ilk(f, g, radius=int(radius))
t = time.perf_counter() - t0
at = lambda field: map_coordinates(field, [y, x], order=1, mode="nearest").tolist()
inside = (slice(y0, y1), slice(x0, x1))
us, vs = u.copy(), v.copy()
us[inside] = gaussian_filter(u[inside], float(sigma), mode="nearest")
vs[inside] = gaussian_filter(v[inside], float(sigma), mode="nearest")
json.dump({"wall_s": t, "ux": at(u), "uy": at(v), "ux_smooth": at(us), "uy_smooth": at(vs)},
          open(out, "w"))
print(json.dumps({"wall_s": t, "nodes": int(x.size)}))
