#!/usr/bin/env python3
"""Is the lateral error of `femu dic` on pymust frames a property of the imaging? Homogeneous
speckle (150 scatterers/mm², no tissue regions, no specular lines, no FE) under analytic motions,
rendered twice from the same scatterers: by pymust with render_pymust.py's settings (its
`Renderer`: SIMUS plane wave, rf2iq, DAS at receive f-number 2.5) and by a shift-invariant
Gaussian IQ point-spread function of pymust's measured size (FWHM 0.155 mm axially, 0.54 mm
laterally, 9 MHz carrier). Each motion's frame is correlated with the unloaded one by `femu dic`
(`--levels 0`: the motions are small) and the lateral error against the exact field is reported
per depth band (columns 60-340 px) and at the lateral edges (the 60 px on each side).

    python bench/independent_us/shift_variance.py --femu target/release/femu --out /tmp/sv

Motions (mm, probe frame: x lateral from the centre, z depth): T, a rigid translation
(-0.73, +1.06) (the first load step's mean motion); SX, a uniform lateral stretch of 4 %
(x -> 1.04 x); CZ, a uniform axial compression of 4 % about 20 mm depth; PS, T with a lateral
stretch of 4.5 % and an axial compression of 4.5 %; SH, a uniform shear, depth + 0.05 x
(`--motions PS,SH`; not among the defaults). `--pitch` changes
the array's pitch at the same aperture (40.2 mm). pymust takes 4-8 min per frame on one core.
"""
import argparse
import os
import subprocess
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render_pymust as rp  # noqa: E402

MOTIONS = {
    "T": lambda q: q + np.array([-0.73, 1.06]),
    "SX": lambda q: np.c_[1.04 * q[:, 0], q[:, 1]],
    "CZ": lambda q: np.c_[q[:, 0], q[:, 1] - 0.04 * (q[:, 1] - 20.0)],
    # The thigh's first load step's mean motion and strains at once.
    "PS": lambda q: np.c_[1.045 * q[:, 0] - 0.77, q[:, 1] + 1.06 - 0.045 * (q[:, 1] - 20.0)],
    # A uniform shear: the axial displacement growing across the window (duy/dx = 0.05).
    "SH": lambda q: np.c_[q[:, 0], q[:, 1] + 0.05 * q[:, 0]],
}
W_PX = H_PX = 400
PX_PER_MM = 10.0
# pymust's measured PSF (README.md): FWHM 0.155 mm axially, 0.54 mm laterally.
SIGMA_X, SIGMA_Z = 0.54 / 2.3548, 0.155 / 2.3548
K2 = 2 * 2 * np.pi * 9e6 / 1540e3  # round-trip wavenumber, rad/mm


def gauss_iq(q, a, alpha=0.0):
    """Shift-invariant IQ image: sum of a * exp(-dx²/2σx² - dz²/2σz² + i k2 dz + i alpha dx²) over
    ±8 x ±3 px (alpha, rad/mm², a lateral phase curvature; 0: none)."""
    img = np.zeros((H_PX, W_PX), complex)
    ic = (q[:, 0] + 0.5 * W_PX / PX_PER_MM) * PX_PER_MM - 0.5
    jc = q[:, 1] * PX_PER_MM - 0.5
    for di in range(-8, 9):
        for dj in range(-3, 4):
            i = np.round(ic).astype(int) + di
            j = np.round(jc).astype(int) + dj
            ok = (i >= 0) & (i < W_PX) & (j >= 0) & (j < H_PX)
            dx, dz = ((i - ic) / PX_PER_MM)[ok], ((j - jc) / PX_PER_MM)[ok]
            np.add.at(img, (j[ok], i[ok]), a[ok] * np.exp(-dx**2 / (2 * SIGMA_X**2) - dz**2 / (2 * SIGMA_Z**2) + 1j * K2 * dz + 1j * alpha * dx**2))
    return img


def render(out, motions, renderers, pitch, seed, apodization="none"):
    s = rp.Settings(pitch_mm=pitch, kerf_mm=0.1 * pitch, n_elements=int(round(40.2 / pitch)),
                    rx_apodization=apodization)
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-23.0, -3.0]), np.array([23.0, 43.0])
    n = rng.poisson(150 * np.prod(hi - lo))
    q0 = lo + rng.random((n, 2)) * (hi - lo)
    amp = rng.standard_normal(n) / np.sqrt(150)
    ren = None
    for r in renderers:
        black = None
        for name in ["ref"] + motions:
            q = q0 if name == "ref" else MOTIONS[name](q0)
            t = time.time()
            if r == "pymust":
                ren = ren or rp.Renderer(s, W_PX, H_PX)
                v = ren.in_view(q)
                env = np.abs(ren.iq_image(q[v], amp[v]))
            else:
                env = np.abs(gauss_iq(q, amp))
            if black is None:  # the reference frame's gain, kept (render_pymust's rule)
                black = 10 * np.log10(np.mean(env[20:380, 20:380] ** 2)) - s.dynamic_db * s.muscle_grey / 255
            rp.save_png(rp.Path(out, f"{r}_{name}.png"), rp.to_grey(env, black, s.dynamic_db))
            print(f"{r} {name}: {time.time() - t:.0f} s", flush=True)


def load_csv(path):
    lines = [l for l in open(path) if not l.startswith("#")]
    hdr = lines[0].strip().split(",")
    a = np.array([[float(v) for v in l.split(",")] for l in lines[1:]])
    return {h: a[:, i] for i, h in enumerate(hdr)}


def evaluate(femu, out, motions, renderers):
    print("\nlateral RMS error (px) against the exact field, by depth band (columns 60-340) and at the edges")
    print("renderer motion   0-5 mm   5-11 mm  11-25 mm  25-40 mm  edges   | axial RMS")
    for r in renderers:
        for name in motions:
            d = os.path.join(out, f"dic_{r}_{name}")
            p = subprocess.run([femu, "dic", os.path.join(out, f"{r}_ref.png"), os.path.join(out, f"{r}_{name}.png"),
                                "--pixel-size", "0.1", "--levels", "0", "--no-figures", "-q", "--out", d],
                               capture_output=True, text=True)
            if p.returncode:
                print(f"{r:8} {name:6} femu dic failed: {p.stderr.strip()[-200:]}")
                continue
            f = load_csv(os.path.join(d, "field.csv"))
            px = np.c_[f["x"], f["y"]] * PX_PER_MM
            u = np.c_[f["ux"], f["uy"]] * PX_PER_MM
            q = np.c_[(px[:, 0] + 0.5) / PX_PER_MM - 20.0, (px[:, 1] + 0.5) / PX_PER_MM]
            e = u - (MOTIONS[name](q) - q) * PX_PER_MM
            w = f["w"] > 0
            mid = w & (px[:, 0] > 60) & (px[:, 0] < 340)
            cells = [np.sqrt(np.mean(e[mid & (px[:, 1] >= a) & (px[:, 1] < b), 0] ** 2))
                     for a, b in ((0, 50), (50, 110), (110, 250), (250, 400))]
            edge = w & ~((px[:, 0] > 60) & (px[:, 0] < 340))
            cells.append(np.sqrt(np.mean(e[edge, 0] ** 2)))
            print(f"{r:8} {name:6} " + "  ".join(f"{c:7.3f}" for c in cells) + f"  | {np.sqrt(np.mean(e[w, 1] ** 2)):.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--out", default="out/shift_variance")
    ap.add_argument("--motions", default="T,SX,CZ")
    ap.add_argument("--renderers", default="gauss,pymust")
    ap.add_argument("--pitch", type=float, default=0.3, help="array pitch, mm (aperture 40.2 mm)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--rx-apodization", choices=["none", "hann"], default="none",
                    help="pymust's receive apodization (render_pymust.py --rx-apodization)")
    ap.add_argument("--evaluate-only", action="store_true")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    motions, renderers = a.motions.split(","), a.renderers.split(",")
    if not a.evaluate_only:
        render(a.out, motions, renderers, a.pitch, a.seed, a.rx_apodization)
    evaluate(a.femu, a.out, motions, renderers)


if __name__ == "__main__":
    main()
