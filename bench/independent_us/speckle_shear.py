#!/usr/bin/env python3
"""Does coherent speckle move laterally under a shear? A shift-invariant Gaussian IQ
point-spread function (shift_variance.py's, 9 MHz carrier, FWHM 0.54 x 0.155 mm) given a
lateral quadratic phase `alpha dx^2` (shift_variance.gauss_iq's `alpha`; a laterally curved wavefront, as away from a focus), on
homogeneous speckle (150 scatterers/mm^2), the scatterers sheared axially (depth + g x, true
lateral displacement zero), each pair correlated by `femu dic` (defaults, `--pixel-size 0.1`).

For such a PSF the speckle pattern of scatterers with a lateral phase ramp `beta x` (here
`beta = -k2 g`, k2 the round-trip wavenumber) is the pattern without the ramp translated laterally
by `beta alpha / (2 (alpha^2 + 1 / (4 sigma^4)))` (sigma the PSF's lateral standard deviation):
completing the square in the complex Gaussian. Without phase curvature (alpha = 0) it does not
move. The script prints the measured lateral mean displacement beside that prediction.

    python bench/independent_us/speckle_shear.py --femu target/release/femu --out /tmp/shear
"""
import argparse
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import render_pymust as rp  # noqa: E402
import psf_phase  # noqa: E402
import shift_variance as sv  # noqa: E402

PX_PER_MM = sv.PX_PER_MM


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--out", default="out/speckle_shear", type=Path)
    ap.add_argument("--shear", type=float, default=0.05, help="g = d(depth displacement)/dx")
    ap.add_argument("--alphas", default="0,10,20,-20", help="lateral phase curvatures, rad/mm^2")
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    lo, hi = np.array([-23.0, -3.0]), np.array([23.0, 43.0])
    n = rng.poisson(150 * np.prod(hi - lo))
    q0 = lo + rng.random((n, 2)) * (hi - lo)
    amp = rng.standard_normal(n) / np.sqrt(150)
    q1 = np.c_[q0[:, 0], q0[:, 1] + a.shear * q0[:, 0]]
    s = rp.Settings()
    # The IQ phase is k2 (depth of the pixel - depth of the scatterer): a scatterer moved by
    # g x takes the phase -k2 g x (beta = -k2 g in psf_phase.closed_form_shift).
    print("alpha (rad/mm^2)  measured lateral mean (px)  RMS (px)  predicted (px)")
    for alpha in [float(v) for v in a.alphas.split(",")]:
        d = a.out / f"alpha_{alpha:g}"
        d.mkdir(parents=True, exist_ok=True)
        env0, env1 = np.abs(sv.gauss_iq(q0, amp, alpha)), np.abs(sv.gauss_iq(q1, amp, alpha))
        black = 10 * np.log10(np.mean(env0[20:380, 20:380] ** 2)) - s.dynamic_db * s.muscle_grey / 255
        rp.save_png(d / "ref.png", rp.to_grey(env0, black, s.dynamic_db))
        rp.save_png(d / "def.png", rp.to_grey(env1, black, s.dynamic_db))
        r = subprocess.run([a.femu, "dic", str(d / "ref.png"), str(d / "def.png"), "--pixel-size", "0.1",
                            "--no-figures", "-q", "--out", str(d / "dic")], capture_output=True, text=True)
        if r.returncode:
            print(f"{alpha:+8.1f}  femu dic failed: {r.stderr.strip()[-200:]}")
            continue
        f = sv.load_csv(d / "dic" / "field.csv")
        px = np.c_[f["x"], f["y"]] * PX_PER_MM
        ux = f["ux"] * PX_PER_MM
        w = (f["w"] > 0) & (px[:, 0] > 60) & (px[:, 0] < 340) & (px[:, 1] > 40) & (px[:, 1] < 360)
        pred = psf_phase.closed_form_shift(sv.K2, alpha, sv.SIGMA_X, a.shear) * PX_PER_MM
        print(f"{alpha:+8.1f}  {ux[w].mean():+26.3f}  {np.sqrt((ux[w] ** 2).mean()):8.3f}  {pred:+14.3f}", flush=True)


if __name__ == "__main__":
    main()
