#!/usr/bin/env python3
"""Recorded-frame route, measured: `femu dic` on a five-frame B-mode sequence (defaults, the
pixel size only), its composed field identified by `femu identify` through `[measurement] file`
with the frames' placement in the model, plain (per-point sx, sy) and weighted (the field's full
covariance), over realizations rendered by pymust (`render_pymust.py`) and by femu's own
renderer (`femu us-sim`, same probe window and loads).

    python bench/independent_us/campaign.py --femu target/release/femu \
        --indep out/indep --seeds 1-10 --own --out out/indep_campaign

Writes `campaign.csv` (one row per renderer, seed, route and parameter: truth, estimate,
relative error, 95 % interval, covered) and `fields.csv` (the composed field's RMS error
against the true field per realization), and prints the summary: mean and largest |error| and
the coverage per renderer, route and parameter, for the parameters under the probe.
"""
import argparse
import csv
import json
import os
import subprocess
import sys
import time

import numpy as np
from scipy.interpolate import griddata

# Table 1 (MPa, MPa^-1): the truth of both renderers.
TRUTH = {"C10_FAT": 0.8e-3, "D_FAT": 30.8, "C10_QUADRICEPS": 1.75e-3, "D_QUADRICEPS": 18.0}
PX = 0.1  # mm per pixel of both renderers' frames


def seeds(text):
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def run(cmd, log):
    t = time.time()
    r = subprocess.run(cmd, capture_output=True, text=True)
    with open(log, "a") as f:
        f.write(" ".join(cmd) + "\n" + r.stdout + r.stderr + "\n")
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:3])}... failed: {r.stderr.strip().splitlines()[-1:]}")
    return time.time() - t


def load_csv(path):
    lines = [l for l in open(path) if not l.startswith("#")]
    hdr = lines[0].strip().split(",")
    a = np.array([[float(v) for v in l.split(",")] for l in lines[1:]])
    return {h: a[:, i] for i, h in enumerate(hdr)}


def study_text(field, frame, elements, seed, covariance=None):
    cov = f'covariance = "{covariance}"\n' if covariance else ""
    return (
        f"[model]\nelements = {elements}\n"
        '[[test]]\nkind = "compression"\nside = "anterior"\nforce_n_per_mm = 0.1\n'
        f'[measurement]\nfile = "{field}"\n{cov}'
        f"origin_mm = [{frame['origin_mm'][0]!r}, {frame['origin_mm'][1]!r}]\n"
        f"x_axis = [{frame['x_axis'][0]!r}, {frame['x_axis'][1]!r}]\n"
        f"y_axis = [{frame['y_axis'][0]!r}, {frame['y_axis'][1]!r}]\n"
        f"[identification]\ngrouped = true\nstarts = 5\nseed = {seed}\n"
    )


def own_frames(femu, seed, out, log):
    """femu's own frames of the same experiment (us-sim, scatterer seed `seed`)."""
    os.makedirs(out, exist_ok=True)
    study = os.path.join(out, "sim.toml")
    with open(study, "w") as f:
        f.write(
            '[[test]]\nkind = "compression"\nside = "anterior"\nforce_n_per_mm = 0.1\n'
            f"[ultrasound]\nseed = {seed}\n"
        )
    sim = os.path.join(out, "sim")
    run([femu, "us-sim", study, "--out", sim, "-q"], log)
    return own_frames_in(sim)


def own_frames_in(sim):
    """The frames of a finished `us-sim` run in `sim`, their placement in the model and the true
    field at the reference pixels."""
    p = json.load(open(os.path.join(sim, "summary.json")))["probe"]
    c, n = np.array(p["centre_mm"]), np.array(p["direction"])
    t = np.array([-n[1], n[0]])
    px = 1.0 / p["px_per_mm"]
    hw = 0.5 * p["width_mm"]
    origin = c + t * (0.5 * px - hw) + 0.5 * px * n
    frame = {k: [float(v) for v in a] for k, a in (("origin_mm", origin), ("x_axis", t), ("y_axis", n))}
    frames = [os.path.join(sim, f"frame_{k:02}.png") for k in range(5)]
    # The true field at the reference pixels (us-sim's true_field.csv, model frame).
    tr = load_csv(os.path.join(sim, "true_field.csv"))
    rel = np.c_[tr["x"], tr["y"]] - origin
    truth = {
        "x_px": rel @ t / px,
        "y_px": rel @ n / px,
        "ux_px": np.c_[tr["ux"], tr["uy"]] @ t / px,
        "uy_px": np.c_[tr["ux"], tr["uy"]] @ n / px,
    }
    return frames, frame, truth


def indep_frames(indep, seed):
    d = os.path.join(indep, f"seed_{seed:02}")
    m = json.load(open(os.path.join(d, "manifest.json")))
    frames = [os.path.join(d, f) for f in m["frames"]]
    return frames, m["measurement"], load_csv(os.path.join(d, f"truth_{len(frames) - 1}.csv"))


def truth_at(truth, x):
    """The true displacement (px) at the points `x` (px), linearly interpolated on the Delaunay
    triangles of the truth's points; NaN outside them and in a triangle with an edge longer than
    twice the truth's spacing (where the truth grid has a hole or ends, e.g. at the femur or at
    the bottom of the frame: a long triangle there interpolates between far points)."""
    from scipy.spatial import Delaunay, cKDTree

    p = np.c_[truth["x_px"], truth["y_px"]]
    tri = Delaunay(p)
    spacing = np.median(cKDTree(p).query(p, k=2)[0][:, 1])
    s = tri.find_simplex(x)
    corners = p[tri.simplices[s]]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(1)
    out = (s < 0) | (edges > 2.0 * spacing)
    tu = np.stack([griddata(p, truth[k], x) for k in ("ux_px", "uy_px")], 1)
    tu[out] = np.nan
    return tu


def field_error(field, truth):
    f = load_csv(field)
    x = np.c_[f["x"], f["y"]] / PX
    u = np.c_[f["ux"], f["uy"]] / PX
    tu = truth_at(truth, x)
    ok = np.isfinite(tu).all(1) & (f["w"] > 0)
    e = (u - tu)[ok]
    return np.sqrt((e**2).mean(0)), int(ok.sum())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--indep", default="out/indep", help="pymust realizations (seed_NN folders)")
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--own", action="store_true", help="also femu's own frames, same seeds")
    ap.add_argument("--elements", type=int, default=4000)
    ap.add_argument("--out", default="out/indep_campaign")
    ap.add_argument("--dic-args", default="", help="further options of `femu dic` (one string, e.g. \"--regularization 32\")")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    log = os.path.join(a.out, "run.log")
    rows, fields = [], []
    renderers = [("pymust", None)] + ([("femu", None)] if a.own else [])
    for renderer, _ in renderers:
        for s in seeds(a.seeds):
            d = os.path.abspath(os.path.join(a.out, f"{renderer}_{s:02}"))
            try:
                if renderer == "pymust":
                    frames, frame, truth = indep_frames(a.indep, s)
                else:
                    frames, frame, truth = own_frames(a.femu, s, d, log)
            except (FileNotFoundError, RuntimeError) as e:
                print(f"{renderer} seed {s}: skipped ({e})", file=sys.stderr)
                continue
            dic = os.path.join(d, "dic")
            try:
                t_dic = run([a.femu, "dic", *frames, "--pixel-size", str(PX), *a.dic_args.split(), "--out", dic, "-q"], log)
            except RuntimeError as e:
                print(f"{renderer} seed {s}: femu dic failed: {e}", file=sys.stderr)
                fields.append({"renderer": renderer, "seed": s, "dic": "failed"})
                continue
            rms, n = field_error(os.path.join(dic, "field.csv"), truth)
            fields.append({"renderer": renderer, "seed": s, "dic": "ok", "rms_ux_px": rms[0],
                           "rms_uy_px": rms[1], "points": n, "dic_s": t_dic})
            cov = os.path.join(dic, "field_covariance.mtx")
            for route, covariance in [("plain", None), ("weighted", cov if os.path.exists(cov) else None)]:
                if route == "weighted" and covariance is None:
                    continue
                study = os.path.join(d, f"{route}.toml")
                with open(study, "w") as f:
                    f.write(study_text(os.path.join(dic, "field.csv"), frame, a.elements, s, covariance))
                out = os.path.join(d, route)
                try:
                    t_id = run([a.femu, "identify", study, "--out", out, "-q"], log)
                except RuntimeError as e:
                    print(f"{renderer} seed {s} {route}: identify failed: {e}", file=sys.stderr)
                    continue
                for p in json.load(open(os.path.join(out, "summary.json")))["parameters"]:
                    if p["name"] not in TRUTH:
                        continue
                    tv = TRUTH[p["name"]]
                    lo, hi = p["ci95"]
                    rows.append({"renderer": renderer, "seed": s, "route": route, "parameter": p["name"],
                                 "truth": tv, "identified": p["identified"],
                                 "error_pct": 100 * (p["identified"] / tv - 1), "ci95_lo": lo, "ci95_hi": hi,
                                 "covered": int(lo <= tv <= hi), "identify_s": t_id})
            print(f"{renderer} seed {s}: composed field RMS ({rms[0]:.3f}, {rms[1]:.3f}) px over {n} points; "
                  + ", ".join(f"{r['route']} {r['parameter']} {r['error_pct']:+.1f}%{'' if r['covered'] else ' (outside)'}"
                              for r in rows if r["renderer"] == renderer and r["seed"] == s), flush=True)
    for name, data in [("campaign.csv", rows), ("fields.csv", fields)]:
        if data:
            keys = sorted({k for r in data for k in r}, key=lambda k: list(data[0]).index(k) if k in data[0] else 99)
            with open(os.path.join(a.out, name), "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=keys)
                w.writeheader()
                w.writerows(data)
    print("\nrenderer route    parameter        mean|err|  max|err|  covered")
    for renderer, _ in renderers:
        for route in ("plain", "weighted"):
            for p in TRUTH:
                r = [x for x in rows if x["renderer"] == renderer and x["route"] == route and x["parameter"] == p]
                if r:
                    e = np.abs([x["error_pct"] for x in r])
                    print(f"{renderer:8} {route:9} {p:16} {e.mean():7.2f} % {e.max():7.2f} %  {sum(x['covered'] for x in r)}/{len(r)}")
    ok = [f for f in fields if f.get("dic") == "ok"]
    for renderer, _ in renderers:
        f = [x for x in ok if x["renderer"] == renderer]
        if f:
            print(f"{renderer}: femu dic converged on {len(f)} of {len([x for x in fields if x['renderer'] == renderer])} sequences; "
                  f"composed RMS lateral {np.mean([x['rms_ux_px'] for x in f]):.3f} (max {max(x['rms_ux_px'] for x in f):.3f}) px, "
                  f"axial {np.mean([x['rms_uy_px'] for x in f]):.3f} (max {max(x['rms_uy_px'] for x in f):.3f}) px")


if __name__ == "__main__":
    main()
