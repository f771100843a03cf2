#!/usr/bin/env python3
"""Integrated DIC on recorded frames, measured: `femu run` with `[measurement] source = "frames"`
on five-frame B-mode sequences rendered by pymust (`render_pymust.py`), one realization at a
time, each placed in the model by its manifest's `measurement` frame (`origin_mm`, `x_axis`,
`y_axis`, `pixel_size_mm`) and loaded by its `loads_n_per_mm` (the unloaded frame's 0 left out).

    python bench/independent_us/idic_campaign.py --femu target/release/femu \
        --indep out/indep --seeds 1-10 --out out/indep_idic

The study is the acceptance campaign's: 4 000 CPE4H elements, compression anterior 0.1 N/mm,
D of ischio, sartorius and gracilis grouped, five starts, every other default. The truth is
Table 1; it is used only to score the estimates, never by the run.

Writes `idic_campaign.csv` (one row per seed, route and parameter: truth, estimate, relative
error, 95 % interval, covered, seen, time; the routes are the integrated DIC and, for comparison,
DIC -> FEMU on the run's composed field, plain and weighted) and `summary.csv` (per route and
parameter under the probe: mean and largest |error|, coverage), and prints the summary. Seeds already in the output folder are read
back, not run again (`--again` runs them again).
"""
import argparse
import csv
import json
import os
import subprocess
import time

# Table 1 (MPa, MPa^-1): the truth of the rendered frames.
TRUTH = {"C10_FAT": 0.8e-3, "D_FAT": 30.8, "C10_QUADRICEPS": 1.75e-3, "D_QUADRICEPS": 18.0}


def seeds(text):
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def study_text(d, manifest, elements):
    m = manifest["measurement"]
    loads = [l for l in manifest["loads_n_per_mm"] if l > 0.0]
    frames = ", ".join(f'"{os.path.join(d, f)}"' for f in manifest["frames"])
    return (
        f"[model]\nelements = {elements}\n"
        '[[test]]\nkind = "compression"\nside = "anterior"\nforce_n_per_mm = 0.1\n'
        '[measurement]\nsource = "frames"\n'
        f"frames = [{frames}]\n"
        f'units = "{m["units"]}"\npixel_size_mm = {m["pixel_size_mm"]!r}\n'
        f"origin_mm = [{m['origin_mm'][0]!r}, {m['origin_mm'][1]!r}]\n"
        f"x_axis = [{m['x_axis'][0]!r}, {m['x_axis'][1]!r}]\n"
        f"y_axis = [{m['y_axis'][0]!r}, {m['y_axis'][1]!r}]\n"
        f"loads_n_per_mm = [{', '.join(repr(l) for l in loads)}]\n"
        '[identification]\ntest = "compression"\ngrouped = true\nstarts = 5\nseed = 1\n'
        "[run]\nforward = false\nsensitivity = false\n"
    )


# The routes a frames run identifies by: integrated DIC (identify/grouped), and, for comparison,
# DIC -> FEMU on the composed field, plain and weighted (identify/grouped/dic, dic-weighted).
ROUTES = ["integrated", "dic-plain", "dic-weighted"]


def routes(params):
    d = os.path.dirname(params)
    out = [("integrated", params)]
    for route, sub in [("dic-plain", "dic"), ("dic-weighted", "dic-weighted")]:
        path = os.path.join(d, sub, "parameters.csv")
        if os.path.isfile(path):
            out.append((route, path))
    return out


def one(femu, indep, seed, out, elements, again):
    d = os.path.abspath(os.path.join(indep, f"seed_{seed:02d}"))
    run_dir = os.path.join(out, f"seed_{seed:02d}")
    params = os.path.join(run_dir, "identify", "grouped", "parameters.csv")
    timing = os.path.join(run_dir, "wall_s.txt")
    if os.path.isfile(params) and os.path.isfile(timing) and not again:
        return params, float(open(timing).read())
    os.makedirs(out, exist_ok=True)
    manifest = json.load(open(os.path.join(d, "manifest.json")))
    study = os.path.join(out, f"seed_{seed:02d}.toml")
    with open(study, "w") as f:
        f.write(study_text(d, manifest, elements))
    t = time.time()
    cmd = ["nice", "-n", "5", femu, "run", study, "--out", run_dir]
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.time() - t
    with open(os.path.join(out, f"seed_{seed:02d}.log"), "w") as f:
        f.write(" ".join(cmd) + "\n" + r.stdout + r.stderr)
    if r.returncode != 0:
        raise RuntimeError(f"seed {seed}: femu run failed: {r.stderr.strip().splitlines()[-3:]}")
    with open(timing, "w") as f:
        f.write(f"{wall:.1f}")
    return params, wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--femu", default="target/release/femu")
    ap.add_argument("--indep", default="out/indep")
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--elements", type=int, default=4000)
    ap.add_argument("--out", default="out/indep_idic")
    ap.add_argument("--again", action="store_true")
    a = ap.parse_args()
    rows = []
    for s in seeds(a.seeds):
        try:
            params, wall = one(a.femu, a.indep, s, a.out, a.elements, a.again)
        except RuntimeError as e:
            print(e, flush=True)
            continue
        for route, path in routes(params):
            for p in csv.DictReader(open(path)):
                if p["name"] not in TRUTH:
                    continue
                tv = TRUTH[p["name"]]
                est = float(p["identified"])
                lo, hi = float(p["ci95_low"]), float(p["ci95_high"])
                rows.append({
                    "seed": s, "route": route, "parameter": p["name"], "truth": tv, "identified": est,
                    "relative_error": est / tv - 1.0, "relative_sd": float(p["relative_sd"]),
                    "ci95_low": lo, "ci95_high": hi, "covered": int(lo <= tv <= hi),
                    "seen": p.get("seen", ""), "wall_s": wall,
                })
        for route in ROUTES:
            got = {r["parameter"]: r for r in rows if r["seed"] == s and r["route"] == route}
            if got:
                print(f"seed {s:2d} {route:12} ({wall:.0f} s): " + ", ".join(
                    f"{k} {100 * r['relative_error']:+.2f} % (sd {100 * r['relative_sd']:.1f} %){'' if r['covered'] else ' MISSED'}"
                    for k, r in got.items()), flush=True)
    if not rows:
        return
    with open(os.path.join(a.out, "idic_campaign.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    summary = []
    for route, p in [(route, p) for route in ROUTES for p in TRUTH]:
        rs = [r for r in rows if r["parameter"] == p and r["route"] == route]
        if not rs:
            continue
        errs = [abs(r["relative_error"]) for r in rs]
        summary.append({
            "route": route, "parameter": p, "realizations": len(rs),
            "mean_abs_error_pct": 100 * sum(errs) / len(errs),
            "max_abs_error_pct": 100 * max(errs),
            "mean_error_pct": 100 * sum(r["relative_error"] for r in rs) / len(rs),
            "covered": sum(r["covered"] for r in rs),
        })
    with open(os.path.join(a.out, "summary.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(summary[0]))
        w.writeheader()
        w.writerows(summary)
    walls = sorted({(r["seed"], r["wall_s"]) for r in rows})
    print("route        parameter         n  mean|err| %  max|err| %  mean err %  covered")
    for s in summary:
        print(f"{s['route']:<12} {s['parameter']:<16} {s['realizations']:2d}  {s['mean_abs_error_pct']:10.2f}  "
              f"{s['max_abs_error_pct']:10.2f}  {s['mean_error_pct']:+10.2f}  {s['covered']}/{s['realizations']}")
    print(f"time per realization: {min(w for _, w in walls):.0f}-{max(w for _, w in walls):.0f} s")


if __name__ == "__main__":
    main()
