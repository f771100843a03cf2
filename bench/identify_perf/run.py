#!/usr/bin/env python3
"""The sensitivity and identification figures of the guide's performance page, measured:

    python3 bench/identify_perf/run.py --femu target/release/femu \
        --sensitivity-cost target/release/examples/sensitivity_cost [--only sensitivity,identify,fd,paper]

- sensitivity: femu-mech's `sensitivity_cost` example (built-in thigh, 25 000 target elements,
  CPE4H, contention and compression interleaved, 3 repeats per run), run 3 times; its lines
  are kept in sensitivity.txt and the per-run summary in sensitivity.csv;
- identify: `femu identify --elements 3000 --repeat 20 --starts 2` (the virtual experiment with
  its defaults); its summary.json kept in identify_3000/;
- paper: the paper-scale identification (25 000 target elements, compression, ungrouped, five
  starts) single-level and multilevel (`coarse_elements = 2000`), one after the other;
  summary.json of each kept in paper_single/ and paper_multi/;
- fd: one start side by side on the coarse model (2 000 target elements, compression, ten
  parameters): Levenberg-Marquardt with exact sensitivities and the seed's BFGS on central
  finite differences (`optimizer = "bfgs-fd"`); fd_lm/ and fd_bfgs/.

The discretization check is off in paper and fd (they time the optimizers, not the check).
The results go to bench/identify_perf/results/ (or --out), each part's folder with its own
provenance.json (scripts/guide/provenance.sh); `scripts/guide/tables.py render
performance.md` makes the page's tables of them. Heavy runs one at a time; run it niced on a
shared machine. About 10 minutes on two cores under a load of 10 (the 20 noise realizations
and the finite-difference BFGS about 2 minutes each).
"""

import argparse
import csv
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent

STUDY = """[model]
elements = {elements}
element = "cpe4h"
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[grid]
counts = [64, 64]
[noise]
sigma_mm = 0.0176
[measurement]
source = "virtual"
[identification]
test = "compression"
grouped = false
optimizer = "{optimizer}"
starts = {starts}
seed = 1
repeat = 1
discretization = "off"
{extra}"""


def provenance(folder, command, femu=None):
    env = dict(os.environ)
    if femu:
        env["FEMU_BIN"] = str(femu)
    subprocess.run(["bash", "-c", '. scripts/guide/provenance.sh; f=$1; shift; write_provenance "$f" "$@"',
                    "provenance", str(folder / "provenance.json"), command], cwd=ROOT, env=env, check=True)


def run(cmd, log):
    print("+", " ".join(map(str, cmd)), file=sys.stderr, flush=True)
    with open(log, "w") as f:
        p = subprocess.run(list(map(str, cmd)), cwd=ROOT, stdout=f, stderr=subprocess.STDOUT)
    if p.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed ({p.returncode}); its output: {log}")


def keep_summary(run_dir, folder):
    """The run's summary.json without each start's step history (the page uses the counts)."""
    s = json.loads((run_dir / "summary.json").read_text())
    for st in s.get("starts", []):
        if st.get("result"):
            st["result"].pop("history", None)
    (folder / "summary.json").write_text(json.dumps(s, indent=1) + "\n")


LINE = re.compile(r"^([\w-]+) #(\d+): solve ([\d.]+) s .*sensitivities ([\d.]+) s = .*rate forces \+ rhs "
                  r"([\d.]+) s, factorization ([\d.]+) s, triangular solves ([\d.]+) s, residuals ([\d.]+) s")


def sensitivity(exe, out, runs=3, elements=25000, repeat=3):
    folder = out / "sensitivity"
    folder.mkdir(parents=True, exist_ok=True)
    provenance(folder, f"python3 bench/identify_perf/run.py --only sensitivity  # {runs} runs of "
                       f"sensitivity_cost {elements} {repeat}")
    text, rows = "", []
    for i in range(runs):
        log = folder / f"run{i + 1}.log"
        run([exe, elements, repeat], log)
        t = log.read_text()
        text += f"## run {i + 1}\n{t}"
        log.unlink()
        for line in t.splitlines():
            m = LINE.match(line)
            if m:
                rows.append({"run": i + 1, "test": m[1], "repeat": int(m[2]), "solve_s": m[3],
                             "sensitivities_s": m[4], "rhs_s": m[5], "factorization_s": m[6],
                             "triangular_s": m[7], "residuals_s": m[8]})
    (folder / "sensitivity.txt").write_text(text)
    with open(folder / "sensitivity.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def identify(femu, out):
    folder = out / "identify_3000"
    folder.mkdir(parents=True, exist_ok=True)
    provenance(folder, "femu identify --elements 3000 --repeat 20 --starts 2", femu)
    with tempfile.TemporaryDirectory() as tmp:
        run([femu, "identify", "--elements", 3000, "--repeat", 20, "--starts", 2, "--out", tmp],
            folder / "log.txt")
        tmp = pathlib.Path(tmp)
        found = sorted(tmp.rglob("summary.json"))
        if not found:
            sys.exit(f"femu identify wrote no summary.json under {tmp}")
        for s in found:
            sub = folder / s.parent.relative_to(tmp)
            sub.mkdir(parents=True, exist_ok=True)
            keep_summary(s.parent, sub)
    (folder / "log.txt").unlink()


def study_run(femu, out, name, command_note, may_fail=False, **keys):
    """One `femu identify STUDY` run: its study, its printed lines (log.txt: each start's cost,
    iterations, forward solves and time) and its summary.json kept in OUT/NAME. MAY_FAIL: a run
    that stops with an error after its starts keeps its log (the error at its end) and no
    summary, instead of stopping the script."""
    folder = out / name
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        study = STUDY.format(**keys)
        (folder / "study.toml").write_text(study)
        provenance(folder, f"femu identify {folder.relative_to(ROOT)}/study.toml  # {command_note}", femu)
        cmd = [femu, "identify", folder / "study.toml", "--out", tmp / "run"]
        if may_fail:
            print("+", " ".join(map(str, cmd)), file=sys.stderr, flush=True)
            with open(folder / "log.txt", "w") as f:
                code = subprocess.run(list(map(str, cmd)), cwd=ROOT, stdout=f, stderr=subprocess.STDOUT).returncode
            if code != 0:
                print(f"{name}: femu identify failed ({code}); its log kept in {folder / 'log.txt'}",
                      file=sys.stderr)
                return
        else:
            run(cmd, folder / "log.txt")
        keep_summary(tmp / "run", folder)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--femu", required=True, type=pathlib.Path)
    ap.add_argument("--sensitivity-cost", type=pathlib.Path,
                    help="femu-mech's sensitivity_cost example (release build)")
    ap.add_argument("--only", default="sensitivity,identify,fd,paper",
                    help="parts to measure, in this order: sensitivity, identify, fd, paper")
    ap.add_argument("--out", type=pathlib.Path, default=ROOT / "bench/identify_perf/results")
    a = ap.parse_args()
    only = set(a.only.split(","))
    unknown = only - {"sensitivity", "identify", "paper", "fd"}
    if unknown:
        sys.exit(f"--only: unknown part(s) {', '.join(sorted(unknown))}")
    out = a.out.resolve()
    femu = a.femu.resolve()
    if only & {"identify", "fd", "paper"} and not femu.is_file():
        sys.exit(f"--femu {a.femu}: no such file (a release build of femu)")
    if "sensitivity" in only and a.sensitivity_cost and not a.sensitivity_cost.is_file():
        sys.exit(f"--sensitivity-cost {a.sensitivity_cost}: no such file (femu-mech's sensitivity_cost example)")
    if "sensitivity" in only:
        if not a.sensitivity_cost:
            sys.exit("--only sensitivity needs --sensitivity-cost EXAMPLE_BINARY")
        sensitivity(a.sensitivity_cost.resolve(), out)
    if "identify" in only:
        identify(femu, out)
    if "fd" in only:
        study_run(femu, out, "fd_lm", "one start, Levenberg-Marquardt", elements=2000,
                  optimizer="lm", starts=1, extra="")
        study_run(femu, out, "fd_bfgs", "one start, BFGS on central finite differences",
                  may_fail=True, elements=2000, optimizer="bfgs-fd", starts=1, extra="")
    if "paper" in only:
        study_run(femu, out, "paper_single", "single level, five starts", elements=25000,
                  optimizer="lm", starts=5, extra="")
        study_run(femu, out, "paper_multi", "multilevel, five starts on 2 000", elements=25000,
                  optimizer="lm", starts=5, extra="coarse_elements = 2000\n")


if __name__ == "__main__":
    main()
