"""muDIC (global Q4, no regularization) on one image pair of a real sequence, for the
comparison with femu-dic (`cargo run --release -p femu-dic --example compare_mudic`).

Usage: python mudic_real.py REF.png DEF.png X Y W H ELEMENT OUT.json [SX SY]
The mesh is femu-dic's: nodes on pixel edges from (X - 0.5, Y - 0.5), ELEMENT px elements over
W x H px. Optional SX SY: an initial rigid shift (pixels; femu-dic's FFT integer shift) given to
muDIC as its nodal starting positions (muDIC starts from zero otherwise and has no pyramid).
Grey levels: BT.601 luminance of RGB, as femu-dic reads them. Writes the nodal positions and
displacements (x = column, y = row, pixels) and the wall time to OUT.json.
"""
import json
import sys
import time

import numpy as np
from PIL import Image
import muDIC as dic

a = sys.argv[1:]
ref, de = a[0], a[1]
x, y, w, h, el = (int(v) for v in a[2:7])
out = a[7]
shift = (float(a[8]), float(a[9])) if len(a) > 9 else (0.0, 0.0)


def grey(p):
    im = np.asarray(Image.open(p).convert("RGB"), dtype=np.float64)
    return 0.299 * im[..., 0] + 0.587 * im[..., 1] + 0.114 * im[..., 2]


imgs = [grey(p) for p in (ref, de)]
t0 = time.perf_counter()
stack = dic.image_stack_from_list(imgs)
mesher = dic.Mesher(deg_e=1, deg_n=1, type="q4")
mesh = mesher.mesh(stack, Xc1=float(x) - 0.5, Xc2=float(x + w) - 0.5, Yc1=float(y) - 0.5,
                   Yc2=float(y + h) - 0.5, n_elx=w // el, n_ely=h // el, GUI=False)
inputs = dic.DICInput(mesh, stack)
inputs.tol = 1e-3
inputs.maxit = 100
if shift != (0.0, 0.0):
    # muDIC's arrays: xnodes = columns? try both conventions at the end; the start is given in
    # its own node arrays (xnodes, ynodes) shifted by the same amounts.
    inputs.node_hist = [np.stack([mesh.xnodes + shift[0], mesh.xnodes + shift[0]], axis=1),
                        np.stack([mesh.ynodes + shift[1], mesh.ynodes + shift[1]], axis=1)]
job = dic.DICAnalysis(inputs)
res = job.run()
t = time.perf_counter() - t0
xn, yn = np.asarray(res.xnodesT), np.asarray(res.ynodesT)
json.dump({"wall_s": t, "x": xn[:, 0].tolist(), "y": yn[:, 0].tolist(),
           "ux": (xn[:, -1] - xn[:, 0]).tolist(), "uy": (yn[:, -1] - yn[:, 0]).tolist()},
          open(out, "w"))
print(json.dumps({"wall_s": t, "nodes": int(xn.shape[0])}))
