#!/usr/bin/env python3
"""Recomputes the composed field's error against the true field (`fields.csv`) of a finished
`campaign.py` run from its output folder, with the evaluation of the current `campaign.py`
(`truth_at`: the truth interpolated only inside the triangles of its own grid). The
identification results (`campaign.csv`) are not touched; `dic_s` is kept from the old file.

    python3 bench/independent_us/reevaluate.py --out OUT --indep out/indep [--write RESULTS_DIR]
"""

import argparse
import csv
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import campaign  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="the campaign's output folder (renderer_NN folders)")
    ap.add_argument("--indep", default="out/indep", help="pymust realizations (seed_NN folders)")
    ap.add_argument("--write", help="folder whose fields.csv is rewritten (default: --out)")
    a = ap.parse_args()
    target = a.write or a.out
    old = {}
    path = os.path.join(target, "fields.csv")
    if os.path.exists(path):
        for r in csv.DictReader(open(path)):
            old[(r["renderer"], int(r["seed"]))] = r
    rows = []
    for name in sorted(os.listdir(a.out)):
        renderer, _, seed = name.partition("_")
        if renderer not in ("pymust", "femu") or not seed.isdigit():
            continue
        s, d = int(seed), os.path.join(a.out, name)
        field = os.path.join(d, "dic", "field.csv")
        if not os.path.exists(field):
            rows.append({"renderer": renderer, "seed": s, "dic": "failed"})
            continue
        if renderer == "pymust":
            _, _, truth = campaign.indep_frames(a.indep, s)
        else:
            # The own frames' truth, from us-sim's output in the campaign folder.
            _, _, truth = campaign.own_frames_in(os.path.join(d, "sim"))
        rms, n = campaign.field_error(field, truth)
        rows.append({"renderer": renderer, "seed": s, "dic": "ok", "rms_ux_px": rms[0], "rms_uy_px": rms[1],
                     "points": n, "dic_s": old.get((renderer, s), {}).get("dic_s", "")})
    rows.sort(key=lambda r: (r["renderer"] != "pymust", r["seed"]))
    keys = ["renderer", "seed", "dic", "rms_ux_px", "rms_uy_px", "points", "dic_s"]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    for renderer in ("pymust", "femu"):
        r = [x for x in rows if x["renderer"] == renderer and x["dic"] == "ok"]
        if r:
            ux, uy = np.array([x["rms_ux_px"] for x in r]), np.array([x["rms_uy_px"] for x in r])
            print(f"{renderer}: {len(r)} fields; RMS lateral {ux.mean():.3f} (max {ux.max():.3f}) px, "
                  f"axial {uy.mean():.3f} (max {uy.max():.3f}) px")


if __name__ == "__main__":
    main()
