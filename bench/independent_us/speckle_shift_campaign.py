#!/usr/bin/env python3
"""`femu identify` with the speckle's lateral shift under shear in its measurement model
(`[measurement] speckle_frequency_mhz`, `speckle_resolution_mm`, `speckle_shift`) on a
campaign's composed DIC fields of pymust frames, beside the campaign's plain route without it.

For each realization of a campaign (campaign.py's folders: `<campaign>/pymust_NN/plain.toml`
reading `dic/field.csv`, the truth and the plain route's result in `campaign.csv`; with
`--renderer femu`, its `femu_NN` realizations of femu's own frames, whose Gaussian
point-spread function has no lateral phase: the scale should come out near 0), the study
is run again with the speckle keys added, once per mode (`fitted`: the shift's scale estimated
with the parameters; `fixed`: the closed form as it is; `true`: held at the scale the true
field supports, see scales.csv below, with `--frames`; `none`: without the keys), and this
script writes:

- `<out>/parameters.csv`: seed, mode, parameter, truth, identified, error (%), 95 % interval,
  covered, and the shift's scale at the optimum (femu's summary.json);
- with `--frames` (the realizations' seed_NN folders of render_pymust.py), `<out>/scales.csv`:
  per realization, the scale the true field supports: the least-squares slope of the composed
  field's lateral error (against render_pymust.py's truth) on `c(z) duy/dx` of the true field
  (columns 60-340 px, trusted points), beside the fitted one, its sd and whether its 95 %
  interval holds the true field's;
- a table per mode on stdout: the error range, mean |error| and 95 % coverage of each
  parameter, beside the uncorrected route's.

With `--dic-args` (and `--frames`) the frames are first correlated again by `femu dic` with
those options (e.g. `"--regularization 32"`) and the studies read that field instead of the
campaign's; the uncorrected columns stay the campaign's own plain route.

    python bench/independent_us/speckle_shift_campaign.py --campaign /tmp/camp_hann \\
        --frequency 9 --resolution 0.907 --femu target/release/femu --out /tmp/ssc_hann
"""
import argparse
import csv
import json
import os
import subprocess

import numpy as np
from scipy.interpolate import griddata

import shear_correction

MODES = ("none", "fitted", "fixed", "true")
PX_PER_MM = 10.0


def true_scale(field_path, truth_path, frequency, resolution):
    """The least-squares scale of c(z) g_true that the composed field's lateral error shows
    (shear_correction.lateral_error's points; g_true by central differences of the truth)."""
    _, header, a = shear_correction.read_field(field_path)
    f = {h: a[:, i] for i, h in enumerate(header)}
    t = np.loadtxt(truth_path, delimiter=",", skiprows=1)
    px = np.c_[f["x"], f["y"]] * PX_PER_MM
    tux = griddata(t[:, :2], t[:, 2], px)
    g = (griddata(t[:, :2], t[:, 3], px + [1, 0]) - griddata(t[:, :2], t[:, 3], px - [1, 0])) / 2
    x = shear_correction.lens_shift_per_shear(frequency, resolution, f["y"] + 0.5 / PX_PER_MM) * g
    e = f["ux"] - tux / PX_PER_MM
    m = (f["w"] > 0) & np.isfinite(tux) & np.isfinite(g) & (px[:, 0] > 60) & (px[:, 0] < 340)
    return float(np.dot(x[m], e[m]) / np.dot(x[m], x[m]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--campaign", required=True, help="campaign.py --out folder")
    ap.add_argument("--frequency", type=float, required=True, help="centre frequency (MHz)")
    ap.add_argument("--resolution", type=float, required=True,
                    help="lateral resolution: FWHM of the point-spread function (mm)")
    ap.add_argument("--modes", default="fitted,fixed", help="comma-separated: none, fitted, fixed")
    ap.add_argument("--dic-args", help="correlate the frames again with these femu dic options "
                                       "(needs --frames) and fit that field")
    ap.add_argument("--route", default="plain", choices=("plain", "weighted"),
                    help="the campaign's study to rerun: plain.toml, or weighted.toml (the field's "
                         "covariance, estimated error)")
    ap.add_argument("--renderer", default="pymust",
                    help="the campaign's realizations to run (pymust, or femu: its own frames)")
    ap.add_argument("--frames", help="folder of the realizations' seed_NN frames (scales.csv)")
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--out", default="out/speckle_shift_campaign")
    a = ap.parse_args()
    modes = [m for m in a.modes.split(",") if m]
    for m in modes:
        if m not in MODES:
            raise SystemExit(f"--modes: unknown mode '{m}' ({', '.join(MODES)})")
    os.makedirs(a.out, exist_ok=True)
    if a.dic_args and not a.frames:
        raise SystemExit("--dic-args needs --frames (the frames to correlate again)")
    if "true" in modes and not a.frames:
        raise SystemExit("--modes true needs --frames (the true field's scale)")
    if a.dic_args and a.route == "weighted":
        raise SystemExit("--dic-args fits the new field with the plain study (the weighted one "
                         "reads the campaign's covariance)")
    campaign = [r for r in csv.DictReader(open(os.path.join(a.campaign, "campaign.csv")))
                if r["renderer"] == a.renderer and r["route"] == a.route]
    seeds = sorted({int(r["seed"]) for r in campaign})
    rows = []
    for seed in seeds:
        src = os.path.join(a.campaign, f"{a.renderer}_{seed:02d}")
        study = open(os.path.join(src, f"{a.route}.toml")).read()
        if "[identification]" not in study:
            raise SystemExit(f"{src}/{a.route}.toml has no [identification] table")
        field = os.path.join(src, "dic", "field.csv")
        if a.dic_args:
            frames = os.path.join(a.frames, f"seed_{seed:02d}")
            paths = sorted((p for p in os.listdir(frames) if p.startswith("frame_") and p.endswith(".png")),
                           key=lambda p: int(p[6:-4]))
            dic = os.path.join(a.out, f"{a.renderer}_{seed:02d}_dic")
            r = subprocess.run([a.femu, "dic", *[os.path.join(frames, p) for p in paths],
                                "--pixel-size", str(1 / PX_PER_MM), *a.dic_args.split(),
                                "--no-figures", "--out", dic, "-q"], capture_output=True, text=True)
            if r.returncode:
                raise SystemExit(f"femu dic {frames}: {r.stderr.strip()[-400:]}")
            if field not in study:
                raise SystemExit(f"{src}/{a.route}.toml does not read {field}")
            study = study.replace(field, os.path.abspath(os.path.join(dic, "field.csv")))
            field = os.path.join(dic, "field.csv")
        held = None
        if "true" in modes:
            frames = os.path.join(a.frames, f"seed_{seed:02d}")
            last = len(json.load(open(os.path.join(frames, "manifest.json")))["truth"])
            held = true_scale(field, os.path.join(frames, f"truth_{last}.csv"), a.frequency,
                              a.resolution)
        for mode in modes:
            keys = "" if mode == "none" else (
                f"speckle_frequency_mhz = {a.frequency}\n"
                f"speckle_resolution_mm = {a.resolution}\n"
                f"speckle_shift = \"{'fixed' if mode == 'true' else mode}\"\n"
                + (f"speckle_scale = {held!r}\n" if mode == "true" else ""))
            dst = os.path.join(a.out, f"{a.renderer}_{seed:02d}_{mode}")
            toml = dst + ".toml"
            with open(toml, "w") as fh:
                fh.write(study.replace("[identification]", keys + "[identification]", 1))
            r = subprocess.run([a.femu, "identify", toml, "--out", dst, "-q"],
                               capture_output=True, text=True)
            if r.returncode:
                raise SystemExit(f"femu identify {toml}: {r.stderr.strip()[-400:]}")
            summary = json.load(open(os.path.join(dst, "summary.json")))
            kappa = summary["speckle_shift"]["scale"] if mode != "none" else 0.0
            kappa_sd = summary["speckle_shift"].get("scale_sd") if mode == "fitted" else None
            got = {p["name"]: p for p in csv.DictReader(open(os.path.join(dst, "parameters.csv")))}
            for row in (c for c in campaign if int(c["seed"]) == seed):
                name, truth = row["parameter"], float(row["truth"])
                p = got[name]
                value, lo, hi = float(p["identified"]), float(p["ci95_low"]), float(p["ci95_high"])
                rows.append({
                    "seed": seed, "mode": mode, "parameter": name, "truth": truth,
                    "identified": value, "error_pct": 100 * (value / truth - 1),
                    "ci95_lo": lo, "ci95_hi": hi, "covered": int(lo <= truth <= hi),
                    "scale": kappa, "scale_sd": "" if kappa_sd is None else kappa_sd,
                    "error_pct_uncorrected": float(row["error_pct"]),
                    "covered_uncorrected": int(row["covered"])})
            print(f"seed {seed} {mode}: scale {kappa:.3f}", flush=True)
    with open(os.path.join(a.out, "parameters.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    if a.frames:
        scales = []
        for seed in seeds:
            frames = os.path.join(a.frames, f"seed_{seed:02d}")
            last = len(json.load(open(os.path.join(frames, "manifest.json")))["truth"])
            if a.dic_args:
                field = os.path.join(a.out, f"{a.renderer}_{seed:02d}_dic", "field.csv")
            else:
                field = os.path.join(a.campaign, f"{a.renderer}_{seed:02d}", "dic", "field.csv")
            row = {"seed": seed, "true_field": true_scale(
                field, os.path.join(frames, f"truth_{last}.csv"), a.frequency, a.resolution)}
            for mode in modes:
                mine = next(r for r in rows if r["seed"] == seed and r["mode"] == mode)
                row[mode] = mine["scale"]
                if mode == "fitted":
                    # Whether the fitted scale's 95 % interval holds the true field's.
                    row["fitted_sd"] = mine["scale_sd"]
                    row["fitted_covers"] = int(abs(mine["scale"] - row["true_field"])
                                               <= 1.96 * mine["scale_sd"])
            scales.append(row)
            print(f"seed {seed}: scale of the true field {row['true_field']:.3f}", flush=True)
        with open(os.path.join(a.out, "scales.csv"), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(scales[0]))
            w.writeheader()
            w.writerows(scales)
    names = list(dict.fromkeys(r["parameter"] for r in rows))
    for mode in modes:
        mine = [r for r in rows if r["mode"] == mode]
        scales = [r["scale"] for r in mine if r["parameter"] == names[0]]
        print(f"\n{mode}: {len(scales)} realizations, scale {min(scales):.3f}..{max(scales):.3f}")
        for n in names:
            sel = [r for r in mine if r["parameter"] == n]
            for tag, e, c in (("uncorrected", "error_pct_uncorrected", "covered_uncorrected"),
                              (mode, "error_pct", "covered")):
                errs = [r[e] for r in sel]
                print(f"  {n:16} {tag:12} {min(errs):+7.1f}..{max(errs):+7.1f} % "
                      f"(mean|e| {sum(abs(x) for x in errs) / len(errs):6.1f}, "
                      f"cov {sum(r[c] for r in sel)}/{len(sel)})")


if __name__ == "__main__":
    main()
