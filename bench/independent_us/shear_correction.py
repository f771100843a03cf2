#!/usr/bin/env python3
"""Does the lateral speckle shift under shear account for the DIC -> FEMU errors on pymust's
apodized frames? Subtract it from femu dic's composed fields and identify again.

psf_phase.py gives, per depth, the lateral shift of pymust's speckle under a shear duy/dx = g
(from the cross-correlation of its measured point-spread function with its sheared self):
c(z) = shift / g, in mm per unit shear (or, with --lens, the closed form of psf_phase.py's
docstring with the focal-plane curvature -k/(2z) and a given lateral resolution). For each realization of a campaign (campaign.py's
folders: `<campaign>/pymust_NN/dic/` with frame_K/field.csv and the composed field.csv,
`plain.toml`), this script writes field.csv with

    ux <- ux - c(depth) duy/dx

(duy/dx by central differences of the field's own uy along its rows), and reports:

- the lateral RMS error against the truth (render_pymust.py's truth_K.csv; columns 60-340 px,
  trusted points) of the first increment's and the composed fields, before and after, and the
  slope of the error against the true lateral displacement (the lateral compression the
  campaigns showed);
- `femu identify` of the study plain.toml on the corrected composed field, beside the
  campaign's plain route on the uncorrected one (campaign.csv): error and 95 % coverage.

    python bench/independent_us/shear_correction.py --psf psf_hann.json --campaign /tmp/camp_hann \\
        --frames /tmp/indep_hann --femu target/release/femu --out /tmp/shear_correction

Writes <out>/lateral.csv, <out>/parameters.csv and the corrected fields and identifications.
"""
import argparse
import csv
import json
import os
import subprocess

import numpy as np
from scipy.interpolate import griddata

import psf_phase

PX_PER_MM = 10.0


def shift_per_shear(psf_json):
    """Depths (mm) and c(z) (mm per unit shear) from psf_phase.py's JSON."""
    psf = json.load(open(psf_json))
    rows = [r for r in psf["rows"] if np.isfinite(r["shift_psf_px"])]
    z = np.array([r["depth_mm"] for r in rows])
    c = np.array([r["shift_psf_px"] for r in rows]) / PX_PER_MM / psf["shear"]
    return z, c


def read_field(path):
    lines = open(path).read().splitlines()
    comments = [l for l in lines if l.startswith("#")]
    body = [l for l in lines if not l.startswith("#")]
    header = body[0].split(",")
    a = np.array([[float(v) for v in l.split(",")] for l in body[1:]])
    return comments, header, a


def shear_of(x, y, uy):
    """duy/dx at the grid points (x, y): central differences along the grid's rows, one-sided
    where a neighbour is missing (the edges, points left out of the field), 0 for a point with
    neither neighbour. Every point is corrected: near the skin, where the grid has gaps, the
    shear is largest."""
    mx, my = np.unique(x), np.unique(y)
    grid = np.full((len(my), len(mx)), np.nan)
    iy, ix = np.searchsorted(my, y), np.searchsorted(mx, x)
    grid[iy, ix] = uy
    left = np.full_like(grid, np.nan)
    right = np.full_like(grid, np.nan)
    left[:, 1:] = (grid[:, 1:] - grid[:, :-1]) / np.diff(mx)
    right[:, :-1] = left[:, 1:]
    # Central differences on an unevenly spaced row: the two sides weighted by the spacings.
    gap_l = np.r_[np.nan, np.diff(mx)]
    gap_r = np.r_[np.diff(mx), np.nan]
    w = gap_r / (gap_l + gap_r)
    both = np.isfinite(left) & np.isfinite(right)
    g = np.where(both, w * left + (1 - w) * right, np.where(np.isfinite(left), left, right))
    return np.nan_to_num(g)[iy, ix]


def lens_shift_per_shear(frequency_mhz, resolution_mm, z_mm, sound_speed=1540.0):
    """c(z) (mm per unit shear) of the closed form with the focal-plane curvature -k/(2z) and a
    Gaussian lateral amplitude of FWHM resolution_mm (psf_phase.py's docstring)."""
    k = 2 * np.pi * frequency_mhz * 1e6 / (sound_speed * 1e3)
    z = np.maximum(np.asarray(z_mm, float), 1e-9)
    sigma = resolution_mm / (2 * np.sqrt(2 * np.log(2)))
    return psf_phase.closed_form_shift(2 * k, -k / (2 * z), sigma, 1.0)


def corrected(path, out, c_of):
    comments, header, a = read_field(path)
    f = {h: a[:, i] for i, h in enumerate(header)}
    g = shear_of(f["x"], f["y"], f["uy"])
    # Depth of a point: its row's centre below the face (the top edge of row 0).
    a[:, header.index("ux")] = f["ux"] - c_of(f["y"] + 0.5 / PX_PER_MM) * g
    with open(out, "w") as fh:
        fh.write("\n".join(comments) + "\n")
        fh.write("# ux corrected for the lateral speckle shift under shear (shear_correction.py)\n")
        fh.write(",".join(header) + "\n")
        for r in a:
            fh.write(",".join(f"{v:.12e}" for v in r) + "\n")


def lateral_error(field_path, truth_path):
    """Lateral RMS error (px) and its slope against the true lateral displacement, columns
    60-340 px, trusted points with a truth."""
    _, header, a = read_field(field_path)
    f = {h: a[:, i] for i, h in enumerate(header)}
    t = np.loadtxt(truth_path, delimiter=",", skiprows=1)
    px = np.c_[f["x"], f["y"]] * PX_PER_MM
    tux = griddata(t[:, :2], t[:, 2], px)
    e = f["ux"] * PX_PER_MM - tux
    m = (f["w"] > 0) & np.isfinite(tux) & (px[:, 0] > 60) & (px[:, 0] < 340)
    return float(np.sqrt(np.mean(e[m] ** 2))), float(np.polyfit(tux[m], e[m], 1)[0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--psf", help="psf_phase.py --json output: c(z) from pymust's measured PSF")
    ap.add_argument("--campaign", required=True, help="campaign.py --out folder")
    ap.add_argument("--frames", required=True, help="folder of the realizations' seed_NN frames")
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--out", default="out/shear_correction")
    ap.add_argument("--lens", metavar="MHZ,FWHM_MM",
                    help="c(z) from the closed form with the focal-plane curvature instead of --psf "
                         "(centre frequency, lateral resolution), e.g. 9,0.907")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    if not (a.lens or a.psf):
        raise SystemExit("give --psf (psf_phase.py --json) or --lens MHZ,FWHM_MM")
    if a.lens:
        f_mhz, fwhm = (float(v) for v in a.lens.split(","))
        c_of = lambda z_mm: lens_shift_per_shear(f_mhz, fwhm, z_mm)  # noqa: E731
    else:
        z, c = shift_per_shear(a.psf)
        c_of = lambda z_mm: np.interp(z_mm, z, c)  # noqa: E731
    campaign = [r for r in csv.DictReader(open(os.path.join(a.campaign, "campaign.csv")))
                if r["renderer"] == "pymust" and r["route"] == "plain"]
    seeds = sorted({int(r["seed"]) for r in campaign})
    lateral_rows, parameter_rows = [], []
    for seed in seeds:
        src = os.path.join(a.campaign, f"pymust_{seed:02d}")
        frames = os.path.join(a.frames, f"seed_{seed:02d}")
        dst = os.path.join(a.out, f"pymust_{seed:02d}")
        os.makedirs(dst, exist_ok=True)
        last = len(json.load(open(os.path.join(frames, "manifest.json")))["truth"])
        for k, field in ((1, os.path.join(src, "dic", "frame_1", "field.csv")),
                         (last, os.path.join(src, "dic", "field.csv"))):
            fixed = os.path.join(dst, f"field_{k}.csv")
            corrected(field, fixed, c_of)
            truth = os.path.join(frames, f"truth_{k}.csv")
            before, after = lateral_error(field, truth), lateral_error(fixed, truth)
            lateral_rows.append({"seed": seed, "frame": k, "rms_before_px": before[0],
                                 "rms_after_px": after[0], "slope_before": before[1],
                                 "slope_after": after[1]})
            print(f"seed {seed} frame {k}: lateral RMS {before[0]:.2f} -> {after[0]:.2f} px, "
                  f"slope {before[1]:+.3f} -> {after[1]:+.3f}", flush=True)
        study = open(os.path.join(src, "plain.toml")).read()
        composed = os.path.join(src, "dic", "field.csv")
        if composed not in study:
            raise SystemExit(f"{src}/plain.toml does not read {composed}")
        toml = os.path.join(dst, "plain.toml")
        with open(toml, "w") as fh:
            fh.write(study.replace(composed, os.path.abspath(os.path.join(dst, f"field_{last}.csv"))))
        out = os.path.join(dst, "plain")
        r = subprocess.run([a.femu, "identify", toml, "--out", out, "-q"], capture_output=True, text=True)
        if r.returncode:
            raise SystemExit(f"femu identify {toml}: {r.stderr.strip()[-400:]}")
        identified = {p["name"]: p for p in csv.DictReader(open(os.path.join(out, "parameters.csv")))}
        for row in campaign:
            if int(row["seed"]) != seed:
                continue
            name, truth = row["parameter"], float(row["truth"])
            p = identified[name]
            value, lo, hi = float(p["identified"]), float(p["ci95_low"]), float(p["ci95_high"])
            parameter_rows.append({
                "seed": seed, "parameter": name, "truth": truth,
                "error_pct_uncorrected": float(row["error_pct"]),
                "covered_uncorrected": int(row["covered"]),
                "identified": value, "error_pct": 100 * (value / truth - 1),
                "ci95_lo": lo, "ci95_hi": hi, "covered": int(lo <= truth <= hi)})
            print(f"  {name:16} {float(row['error_pct']):+8.1f} % -> {100 * (value / truth - 1):+7.1f} % "
                  f"(covered {row['covered']} -> {int(lo <= truth <= hi)})", flush=True)
    for name, rows in (("lateral.csv", lateral_rows), ("parameters.csv", parameter_rows)):
        with open(os.path.join(a.out, name), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
