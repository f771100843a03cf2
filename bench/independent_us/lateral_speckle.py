#!/usr/bin/env python3
"""How wide may the lateral speckle be before `femu dic` loses the lateral component? B-mode
speckle is several times longer laterally than axially, and how much depends on the scanner:
femu's own renderer and render_pymust.py's defaults give 4-5 px lateral speckle at 0.1 mm
pixels, the shared GE Logiq E9 frames 10 px (femu dic's `speckle_fwhm_px`). This script renders
the first load step of femu's default compression (render_pymust.py's FE truth and probe window,
its scatterers moved by the FE displacement) with a shift-invariant Gaussian point-spread
function of several widths, and the same widths under analytic motions of homogeneous speckle,
correlates each unloaded/loaded pair with `femu dic` (defaults, `--pixel-size 0.1`) and reports
the field's error against the exact one.

    python bench/independent_us/lateral_speckle.py --femu target/release/femu --out /tmp/ls

Point-spread function: shift_variance.py's Gaussian IQ PSF (9 MHz carrier) with FWHM
0.54 mm x `lateral` laterally and 0.155 mm x `axial` axially (pymust's measured PSF at factor 1).
Phantom `plain`: render_pymust.py's scatterers with one echo level everywhere, no specular line
and no texture (150 per mm^2): only the motion differs from the analytic cases. Motion `fe`: the
FE displacement of the first load step (0.025 N/mm) in one increment; `fe2`: the same reached in
two equal increments (three frames, composed by `femu dic`'s sequence route); `PSR`: shift_variance.py's homogeneous
speckle translated by (-0.77, +1.06) mm, stretched 4.5 % laterally, compressed 4.5 % axially
and sheared 2.2 % (about the first step's mean strains). Errors are over the points of the
field with w > 0 between columns 60 and 340 (the lateral edges left out), against the truth of
render_pymust.py (truth_1.csv) or the analytic motion. Writes `results.csv` in `--out`.
"""
import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import campaign  # noqa: E402
import render_pymust as rp  # noqa: E402
import shift_variance as sv  # noqa: E402

FWHM_X, FWHM_Z = 0.54, 0.155  # mm, pymust's measured PSF (README.md)
PSR = lambda q: np.c_[1.045 * q[:, 0] - 0.77 + 0.022 * (q[:, 1] - 20),  # noqa: E731
                      q[:, 1] + 1.06 - 0.045 * (q[:, 1] - 20.0) - 0.022 * q[:, 0]]
WIDTHS = [(1.0, 1.0), (1.5, 1.0), (2.0, 1.0), (1.0, 2.0), (2.0, 2.0), (1.85, 2.5)]


def set_psf(lateral, axial):
    sv.SIGMA_X = FWHM_X * lateral / 2.3548
    sv.SIGMA_Z = FWHM_Z * axial / 2.3548


def render_fe(out: Path, fe_cache: Path, seed: int, increments: int):
    """The default realization's unloaded frame and its first load step reached in
    `increments` equal increments of the FE displacement (frames 0..increments), with the
    Gaussian PSF set by set_psf, plain phantom. Returns the frames and the truth of the last."""
    saved = (rp.Renderer.iq_image, rp.SKIN_ECHO_DB, rp.FASCIA_ECHO_DB, rp.BONE_ECHO_DB, dict(rp.ECHO_DB),
             rp.solve_fe)
    solve_fe = rp.solve_fe

    def first_step_in_increments(s, cache=None, log=print):
        fe = dict(solve_fe(s, cache, log))
        fe["u"] = np.stack([fe["u"][0] * k / increments for k in range(1, increments + 1)])
        return fe

    try:
        rp.solve_fe = first_step_in_increments
        rp.Renderer.iq_image = lambda self, q, rc: sv.gauss_iq(q, rc)
        rp.SKIN_ECHO_DB = rp.FASCIA_ECHO_DB = rp.BONE_ECHO_DB = -300.0  # no specular line
        for k in rp.ECHO_DB:
            rp.ECHO_DB[k] = 0.0
        s = rp.Settings(texture_db=0.0, fat_density_per_mm2=rp.Settings().muscle_density_per_mm2)
        rp.realization(seed, out, s, fe_cache, log=lambda m: None)
    finally:
        rp.Renderer.iq_image, rp.SKIN_ECHO_DB, rp.FASCIA_ECHO_DB, rp.BONE_ECHO_DB, echo, rp.solve_fe = saved
        rp.ECHO_DB.clear()
        rp.ECHO_DB.update(echo)
    frames = [out / f"frame_{k}.png" for k in range(increments + 1)]
    return frames, campaign.load_csv(out / f"truth_{increments}.csv")


def render_analytic(out: Path, seed: int):
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-23.0, -3.0]), np.array([23.0, 43.0])
    n = rng.poisson(150 * np.prod(hi - lo))
    q0 = lo + rng.random((n, 2)) * (hi - lo)
    amp = rng.standard_normal(n) / np.sqrt(150)
    s = rp.Settings()
    out.mkdir(parents=True, exist_ok=True)
    black = None
    paths = []
    for k, q in enumerate([q0, PSR(q0)]):
        env = np.abs(sv.gauss_iq(q, amp))
        if black is None:
            black = 10 * np.log10(np.mean(env[20:380, 20:380] ** 2)) - s.dynamic_db * s.muscle_grey / 255
        paths.append(out / f"frame_{k}.png")
        rp.save_png(paths[-1], rp.to_grey(env, black, s.dynamic_db))
    return paths


def correlate(femu, frames, out):
    r = subprocess.run([femu, "dic", *map(str, frames), "--pixel-size", "0.1", "--no-figures",
                        "-q", "--out", str(out)], capture_output=True, text=True)
    if r.returncode:
        return None, r.stderr.strip().splitlines()[-1][:200]
    return json.loads((out / "summary.json").read_text()), None


def errors(field, truth):
    """Lateral and axial (mean, RMS) error (px) inside columns 60-340, and the point count."""
    f = campaign.load_csv(field)
    x = np.c_[f["x"], f["y"]] / campaign.PX
    u = np.c_[f["ux"], f["uy"]] / campaign.PX
    tu = truth(x)
    ok = np.isfinite(tu).all(1) & (f["w"] > 0) & (x[:, 0] > 60) & (x[:, 0] < 340)
    e = (u - tu)[ok]
    return e.mean(0), np.sqrt((e**2).mean(0)), int(ok.sum())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--out", default="out/lateral_speckle", type=Path)
    ap.add_argument("--fe-cache", type=Path, default=Path("out/indep/fe_cache_16000_4.npz"),
                    help="render_pymust.py's FE solution (solved and written there if absent)")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for lateral, axial in WIDTHS:
        set_psf(lateral, axial)
        tag = f"x{lateral:g}_z{axial:g}"
        fw = None
        for motion in ("fe", "fe2", "PSR"):
            d = a.out / f"{motion}_{tag}"
            if motion.startswith("fe"):
                frames, t = render_fe(d, a.fe_cache, a.seed, 2 if motion == "fe2" else 1)
                truth = lambda x, t=t: campaign.truth_at(t, x)  # noqa: E731
            else:
                frames = render_analytic(d, a.seed)

                def truth(x):
                    q = np.c_[(x[:, 0] + 0.5) / 10 - 20.0, (x[:, 1] + 0.5) / 10]
                    return (PSR(q) - q) * 10

            summary, failure = correlate(a.femu, frames, d / "dic")
            row = {"motion": motion, "psf_lateral_factor": lateral, "psf_axial_factor": axial,
                   "psf_fwhm_mm": f"{FWHM_X * lateral:.3f} x {FWHM_Z * axial:.3f}"}
            if summary is None:
                row["dic"] = "failed: " + failure
            else:
                mean, rms, n = errors(d / "dic" / "field.csv", truth)
                # A pair's summary holds its ladder's choice; a sequence's, each increment's.
                first = (summary["increments"][0] if "increments" in summary
                         else {"regularization_px": summary["choice"]["regularization_px"],
                               "residual_percent_of_dynamic": summary["result"]["residual_percent_of_dynamic"]})
                # The speckle as a pair's ladder measured it (a sequence's summary has none:
                # the same PSF's pair row before it).
                fw = summary.get("choice", {}).get("statistics", {}).get("speckle_fwhm_px", fw)
                row.update({
                    "dic": "ok", "speckle_fwhm_px": f"{fw[0]:.1f} x {fw[1]:.1f}" if fw else "",
                    "regularization_px": first["regularization_px"],
                    "residual_percent": round(first["residual_percent_of_dynamic"], 1), "points": n,
                    "lateral_mean_px": round(mean[0], 3), "lateral_rms_px": round(rms[0], 3),
                    "axial_mean_px": round(mean[1], 3), "axial_rms_px": round(rms[1], 3)})
            rows.append(row)
            print(", ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(a.out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
