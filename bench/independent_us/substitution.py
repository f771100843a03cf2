#!/usr/bin/env python3
"""Where the DIC -> FEMU route's error comes from, measured by substitution: the composed field
of a campaign realization (`campaign.py`'s output) is identified again with parts of it
replaced by the true field, or with per-point standard deviations equal to the field's actual
error (an oracle weighting no estimate can beat), and the identified parameters are compared
with the truth.

    python bench/independent_us/substitution.py --femu target/release/femu \
        --campaign out/indep_campaign --indep out/indep --seeds 1-3 --out out/substitution

Variants (each a `femu identify` of the realization's plain study with another field file):
- `measured`: the composed field as measured (the campaign's plain route, run again);
- `true`: the true field at the same points (the model's own bias: mesh, placement);
- `true-lateral`: the true lateral component everywhere, the measured axial one;
- `true-axial`: the true axial component everywhere, the measured lateral one;
- `true-top`: the true lateral component in the top 11 mm (skin, fat, fascia);
- `oracle-sd`: the measured field, sx and sy replaced by the RMS of its actual error in 5 mm
  depth bands (the weighting a perfect error model of that form would give);
- `lateral-x10`: the measured field, the lateral sd sx ten times larger (the lateral component
  weighs a hundredth);
- `axial-only`: the measured field, sx ten thousand times larger (the axial component alone).

Writes `substitution.csv` (seed, variant, parameter, error %, covered) and prints a table of
mean |error| per variant and parameter; `lateral_strain.csv` (seed, the fat layer's mean lateral
strain dux/dx between 3 and 11 mm deep, true and measured, over the trusted points with a truth). The truth is used to build the variants and to score
them: these are diagnostics, not estimates.
"""
import argparse
import csv
import json
import os
import subprocess
import sys

import numpy as np
from scipy.interpolate import griddata

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from campaign import PX, TRUTH, indep_frames, load_csv, seeds  # noqa: E402

VARIANTS = ["measured", "true", "true-lateral", "true-axial", "true-top", "oracle-sd", "lateral-x10",
            "axial-only"]


def true_at(field, truth):
    """The true displacement (mm) at the field's points, NaN outside the truth's grid."""
    x = np.c_[field["x"], field["y"]] / PX
    return np.stack(
        [griddata(np.c_[truth["x_px"], truth["y_px"]], truth[k], x) for k in ("ux_px", "uy_px")], 1
    ) * PX


def variant_rows(field, tu, variant):
    """Rows (x, y, ux, uy, sx, sy, w) of `variant`; points without a truth keep w."""
    ok = np.isfinite(tu).all(1) & (field["w"] > 0)
    ux, uy = field["ux"].copy(), field["uy"].copy()
    sx, sy = field["sx"].copy(), field["sy"].copy()
    if variant == "true":
        ux[ok], uy[ok] = tu[ok, 0], tu[ok, 1]
    elif variant == "true-lateral":
        ux[ok] = tu[ok, 0]
    elif variant == "true-axial":
        uy[ok] = tu[ok, 1]
    elif variant == "true-top":
        top = ok & (field["y"] < 11.0)
        ux[top] = tu[top, 0]
    elif variant == "lateral-x10":
        sx = sx * 10.0
    elif variant == "axial-only":
        sx = sx * 1e4
    elif variant == "oracle-sd":
        band = np.minimum((field["y"] // 5.0).astype(int), 7)
        e = np.c_[ux, uy] - tu
        for b in range(8):
            m = ok & (band == b)
            if m.sum() >= 3:
                sx[band == b] = np.sqrt((e[m, 0] ** 2).mean())
                sy[band == b] = np.sqrt((e[m, 1] ** 2).mean())
    keep = ok if variant in ("true",) else np.ones(len(ux), bool)
    return [(field["x"][i], field["y"][i], ux[i], uy[i], sx[i], sy[i], field["w"][i])
            for i in range(len(ux)) if keep[i]]


def lateral_strain(field, tu):
    """The mean lateral strain dux/dx of the true and of the measured field between 3 and 11 mm
    deep (skin to fascia; a plane fitted to ux over x and y), on the trusted points with a truth."""
    m = np.isfinite(tu).all(1) & (field["w"] > 0) & (field["y"] >= 3.0) & (field["y"] < 11.0)
    a = np.c_[np.ones(m.sum()), field["x"][m] - field["x"][m].mean(), field["y"][m] - field["y"][m].mean()]
    fit = lambda u: np.linalg.lstsq(a, u, rcond=None)[0][1]
    return fit(tu[m, 0]), fit(field["ux"][m])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--campaign", default="out/indep_campaign", help="campaign.py's --out")
    ap.add_argument("--indep", default="out/indep")
    ap.add_argument("--seeds", default="1-3")
    ap.add_argument("--out", default="out/substitution")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, of: " + ", ".join(VARIANTS))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows, strains = [], []
    for s in seeds(a.seeds):
        src = os.path.join(a.campaign, f"pymust_{s:02}")
        path = os.path.join(src, "dic", "field.csv")
        if not os.path.isfile(path):
            print(f"seed {s}: no composed field in {src}", file=sys.stderr)
            continue
        comments = [l.rstrip("\n") for l in open(path) if l.startswith("#")]
        field = load_csv(path)
        _, _, truth = indep_frames(a.indep, s)
        tu = true_at(field, truth)
        true_strain, measured_strain = lateral_strain(field, tu)
        strains.append({"seed": s, "true": true_strain, "measured": measured_strain})
        study = open(os.path.join(src, "plain.toml")).read()
        for v in a.variants.split(","):
            if v not in VARIANTS:
                raise SystemExit(f"unknown variant {v!r}; known: {', '.join(VARIANTS)}")
            d = os.path.abspath(os.path.join(a.out, f"pymust_{s:02}", v))
            os.makedirs(d, exist_ok=True)
            fpath = os.path.join(d, "field.csv")
            with open(fpath, "w") as f:
                f.write("\n".join(comments) + "\nx,y,ux,uy,sx,sy,w\n")
                for r in variant_rows(field, tu, v):
                    f.write(",".join(repr(float(c)) for c in r) + "\n")
            toml = os.path.join(d, "study.toml")
            with open(toml, "w") as f:
                f.write("\n".join(
                    f'file = "{fpath}"' if l.startswith("file = ") else l for l in study.splitlines()
                ) + "\n")
            r = subprocess.run([a.femu, "identify", toml, "--out", os.path.join(d, "identify"), "-q"],
                               capture_output=True, text=True)
            if r.returncode != 0:
                print(f"seed {s} {v}: identify failed: {r.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                continue
            for p in json.load(open(os.path.join(d, "identify", "summary.json")))["parameters"]:
                if p["name"] in TRUTH:
                    tv = TRUTH[p["name"]]
                    lo, hi = p["ci95"]
                    rows.append({"seed": s, "variant": v, "parameter": p["name"],
                                 "error_pct": 100 * (p["identified"] / tv - 1),
                                 "covered": int(lo <= tv <= hi)})
            print(f"seed {s} {v:12}: " + ", ".join(
                f"{x['parameter']} {x['error_pct']:+.1f}%" for x in rows if x["seed"] == s and x["variant"] == v),
                flush=True)
    if strains:
        with open(os.path.join(a.out, "lateral_strain.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(strains[0]))
            w.writeheader()
            w.writerows(strains)
    if not rows:
        return
    with open(os.path.join(a.out, "substitution.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("\nvariant       " + "".join(f"{p:>16}" for p in TRUTH) + "   (mean |error| %)")
    for v in VARIANTS:
        cells = []
        for p in TRUTH:
            e = [abs(x["error_pct"]) for x in rows if x["variant"] == v and x["parameter"] == p]
            cells.append(f"{np.mean(e):16.1f}" if e else f"{'':>16}")
        print(f"{v:13} " + "".join(cells))


if __name__ == "__main__":
    main()
