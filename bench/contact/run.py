#!/usr/bin/env python3
"""The rigid-body contact tests on the built-in thigh, measured: Newton iterations, increments,
cut-backs, solve time and peak memory, and how far the default solve is from a tight one.

    python3 bench/contact/run.py [--example BIN] [--runs N] [--results DIR]

For the seed's compression (flat plate) and indentation (cylinder R = 10 mm), 0.1 N/mm,
anterior, femur fixed, on the built-in thigh at 4 000 and 25 000 target elements (CPE4H), it
runs femu-mech's `contact_cost` example (built with `cargo build --release -p femu-mech
--example contact_cost` unless --example names a binary):

- once with tight tolerances (residual 1e-12, energy 1e-24, penetration 1e-12 of the element
  size), writing that final state;
- N times with the default settings, comparing each final state with the tight one (largest
  nodal difference over the largest nodal displacement), timing setup + solve (the example's own
  clock), the CPU time of the whole process (user + system; on a loaded machine a steadier
  figure than the wall time) and its peak resident memory (`/usr/bin/time -v`).

It writes DIR/contact.csv (one row per case: the medians over the runs and their spread) and
DIR/provenance.json (date, machine, commit, command), from which
`python3 scripts/guide/tables.py render contact.md` makes the guide's contact page. About a
minute on two cores.
"""

import argparse
import csv
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
CASES = [
    ("compression", 4000),
    ("indentation", 4000),
    ("compression", 25000),
    ("indentation", 25000),
]
TIGHT = ["residual_tolerance=1e-12", "energy_tolerance=1e-24", "penetration_tolerance=1e-12"]


def run(cmd):
    """Runs `cmd` under /usr/bin/time -v: (stdout, peak resident memory in MiB, CPU seconds of
    the whole process)."""
    p = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{p.stdout}\n{p.stderr}")
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    cpu = sum(float(x) for x in re.findall(r"(?:User|System) time \(seconds\): ([\d.]+)", p.stderr))
    return p.stdout, (int(rss.group(1)) / 1024 if rss else None), cpu


def parse(out):
    """What the example prints: elements, iterations, increments, cut-backs, solve time,
    difference from the reference."""
    r = {}
    m = re.search(r": (\d+) elements", out)
    r["elements"] = int(m.group(1))
    m = re.search(r"(\d+) increments, (\d+) cut-backs, (\d+) Newton iterations; setup \+ solve ([\d.]+) s", out)
    r["increments"], r["cutbacks"], r["iterations"] = int(m.group(1)), int(m.group(2)), int(m.group(3))
    r["solve_s"] = float(m.group(4))
    m = re.search(r"largest difference from \S+: ([\d.e+-]+) of", out)
    r["difference"] = float(m.group(1)) if m else None
    m = re.search(r"travel ([\d.]+) mm", out)
    r["travel_mm"] = float(m.group(1))
    return r


def example_binary(given):
    if given:
        return Path(given)
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "femu-mech", "--example", "contact_cost"],
                   cwd=ROOT, check=True)
    target = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=ROOT,
                            capture_output=True, text=True, check=True)
    return Path(json.loads(target.stdout)["target_directory"]) / "release/examples/contact_cost"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--example", help="a built contact_cost example (default: build it)")
    ap.add_argument("--runs", type=int, default=3, help="default-settings solves per case (median)")
    ap.add_argument("--results", type=Path, default=HERE / "results")
    a = ap.parse_args()
    exe = example_binary(a.example)
    a.results.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for test, elements in CASES:
            ref = Path(tmp) / f"{test}_{elements}.txt"
            out, _, _ = run([exe, test, str(elements), "cpe4h"] + TIGHT + [f"write={ref}"])
            tight = parse(out)
            runs = []
            for _ in range(a.runs):
                out, rss, cpu = run([exe, test, str(elements), "cpe4h", f"compare={ref}"])
                r = parse(out)
                r["rss_mib"] = rss
                r["cpu_s"] = cpu
                runs.append(r)
            first = runs[0]
            # The Newton history is deterministic: every run takes the same iterations.
            assert all((r["iterations"], r["increments"], r["cutbacks"]) ==
                       (first["iterations"], first["increments"], first["cutbacks"]) for r in runs)
            t = [r["solve_s"] for r in runs]
            m = [r["rss_mib"] for r in runs]
            c = [r["cpu_s"] for r in runs]
            rows.append({
                "test": test,
                "elements": first["elements"],
                "iterations": first["iterations"],
                "increments": first["increments"],
                "cutbacks": first["cutbacks"],
                "solve_s_median": f"{statistics.median(t):.3f}",
                "solve_s_min": f"{min(t):.3f}",
                "solve_s_max": f"{max(t):.3f}",
                "process_cpu_s_median": f"{statistics.median(c):.2f}",
                "peak_mib_median": f"{statistics.median(m):.0f}",
                "difference_from_tight": f"{first['difference']:.2e}",
                "tight_iterations": tight["iterations"],
                "travel_mm": f"{first['travel_mm']:.4f}",
                "runs": a.runs,
            })
            print(rows[-1], file=sys.stderr)
    with open(a.results / "contact.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cmd = "python3 bench/contact/run.py " + " ".join(sys.argv[1:])
    subprocess.run(["bash", "-c", '. scripts/guide/provenance.sh; write_provenance "$0" "$1"',
                    str(a.results / "provenance.json"), cmd], cwd=ROOT, check=True)


if __name__ == "__main__":
    main()
