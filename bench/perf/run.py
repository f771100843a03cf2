#!/usr/bin/env python3
"""Performance figures of femu, measured side by side for two binaries.

For each figure it prints the goal and the value for the current binary and for a previous one,
the two run in turn (previous, current, previous, current, ...) so that both see the same load of
the machine, and writes the table to bench/perf/results.md.

    python3 bench/perf/run.py [--prev PREV_BINARY] [--cur CUR_BINARY] [--runs N] [--only NAMES]

The previous binary defaults to a release build of the commit in --prev-commit (d9ac6d3), made
once into /tmp/femu_prev (a git worktree and a target directory of its own: about 10 minutes on
two cores). The current one defaults to target/release/femu of this checkout (built first).

Figures (NAMES for --only in brackets):
- [dic1024], [dic512]: `femu dic` on a synthetic speckle pair (speckle.py), the whole command's
  wall time over the correlation's own time (summary.json result.timings.total_s); goal <= 2x.
- [mudic]: `femu dic` (the whole command, default options and outputs) against muDIC on the same
  speckle pair, 1024 x 1024 and 512 x 512, over the same ROI (the image less two elements at each
  edge, where muDIC cannot mesh), muDIC with the same 16 px Q4 mesh and the same increment tolerance (crates/femu-dic/bench/mudic_bench.py, run by
  --mudic-python, a Python with muDIC; the figure is skipped without it): muDIC's time over
  femu's, goals >= 50x at 1024^2 and >= 10x at 512^2, and both nodal RMS errors against the
  pair's known affine field. One muDIC run per size (about 45 s at 1024^2), femu --runs times;
  muDIC's time is its analysis alone (mesh and correlation, in the Python process), femu's the
  whole command (reading the images, every output).
- [idic]: integrated DIC of one realization at 4 000 elements: `femu run` of a study with
  [measurement] source = "ultrasound" (compression, probe anterior 40 x 40 mm, grouped, 5
  starts); the identification step's wall time (identify/grouped/summary.json wall_time_s);
  goal <= 10 s. The whole `femu run` is given beside it.
- [demo]: `femu demo` wall time, goal <= 8 s.
- [full]: `femu demo --full` wall time and peak memory (maximum resident set size from
  /usr/bin/time -v), goals <= 15 s and <= 400 MB.
- [bench]: `femu bench`: CalculiX's time over femu's on the paper-scale contention deck (median
  of the bench's own interleaved runs); goal >= 50x. The `femu solve` of that deck by both
  binaries, side by side, is given beside it.

Each value is the median over the runs; the spread (min-max) is printed beside it.

Beside results.md it writes the same table as data, from which the guide's Performance page is
generated (`python3 scripts/guide/tables.py performance bench/perf/results`): --results DIR
(default bench/perf/results) receives results.json (the rows, the binaries and their commits)
and provenance.json (date, machine, commit, load average at the start, command).
"""

import argparse
import datetime
import json
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import speckle  # this folder: the speckle pair and its known field

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
IDIC_STUDY = """[model]
elements = 4000
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[measurement]
source = "ultrasound"
[probe]
side = "anterior"
width_mm = 40
depth_mm = 40
[ultrasound]
frequency_mhz = 9
seed = 1
[identification]
grouped = true
starts = 5
seed = 1
[run]
forward = false
sensitivity = false
"""


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def timed(cmd: list, cwd: Path, timeout: float) -> dict:
    """Runs `cmd` under /usr/bin/time -v; returns wall (s), peak RSS (MB) and the exit code."""
    with tempfile.NamedTemporaryFile("r", suffix=".time", delete=False) as f:
        tfile = f.name
    try:
        p = subprocess.run(
            ["/usr/bin/time", "-v", "-o", tfile, *map(str, cmd)],
            cwd=cwd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            timeout=timeout,
            text=True,
        )
        text = Path(tfile).read_text()
    finally:
        os.unlink(tfile)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", text).group(1)
    parts = [float(x) for x in wall.split(":")]
    seconds = sum(v * 60 ** (len(parts) - 1 - i) for i, v in enumerate(parts))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1)) / 1024
    if p.returncode != 0:
        log(f"  exit {p.returncode}: {' '.join(map(str, cmd))}\n{p.stderr[-2000:]}")
    return {"wall": seconds, "rss_mb": rss, "code": p.returncode}


def med(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def spread(values, fmt):
    values = [v for v in values if v is not None]
    if not values:
        return "n/a"
    if len(values) == 1:
        return fmt.format(values[0])
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}-{fmt.format(max(values))})"


def interleaved(binaries: dict, runs: int, one_run) -> dict:
    """Runs `one_run(label, binary, k)` for every binary in turn, `runs` times; its results per
    label, in run order."""
    out = {label: [] for label in binaries}
    for k in range(runs):
        for label, binary in binaries.items():
            out[label].append(one_run(label, binary, k))
    return out


def figure_dic(binaries, runs, work, size):
    pair = work / f"speckle{size}"
    if not (pair / "def.png").exists():
        subprocess.run([sys.executable, HERE / "speckle.py", str(size), pair], check=True)

    def one(label, binary, k):
        out = work / f"dic{size}_{label}"
        shutil.rmtree(out, ignore_errors=True)
        t = timed([binary, "dic", pair / "ref.png", pair / "def.png", "--out", out, "-q"], work, 600)
        try:
            s = json.loads((out / "summary.json").read_text())
            corr = s["result"]["timings"]["total_s"]
        except (OSError, KeyError, ValueError):
            return None
        # Every rung of the ladder's correlation time, when the binary reports it per attempt.
        rungs = [a.get("correlation_s") for a in s.get("choice", {}).get("attempts", [])]
        corr_all = sum(rungs) if rungs and None not in rungs else None
        log(f"  dic {size}^2 {label}: wall {t['wall']:.2f} s, correlation {corr:.2f} s"
            + (f", every rung {corr_all:.2f} s" if corr_all else ""))
        return {"wall": t["wall"], "corr": corr, "ratio": t["wall"] / corr,
                "ratio_all": corr_all and t["wall"] / corr_all}

    res = interleaved(binaries, runs, one)
    cell = {
        label: spread([r and r["ratio"] for r in rs], "{:.2f}x")
        + f"; wall {spread([r and r['wall'] for r in rs], '{:.2f}')} s"
        for label, rs in res.items()
    }
    cell_all = {
        label: spread([r and r["ratio_all"] for r in rs], "{:.2f}x")
        if all(r and r["ratio_all"] for r in rs) else "- (not reported)"
        for label, rs in res.items()
    }
    return [
        (f"`femu dic` {size}x{size} speckle pair: wall time / correlation time", "<= 2x", cell),
        (f"`femu dic` {size}x{size}: wall time / every rung's correlation time", "-", cell_all),
    ]


def figure_mudic(binaries, runs, work, python):
    """`femu dic` (both binaries) against muDIC on the speckle pairs of figure_dic."""
    rows = []
    script = ROOT / "crates/femu-dic/bench/mudic_bench.py"
    # speckle.py's known field: a translation and a gradient about the image centre.
    shift = [str(v) for v in speckle.SHIFT]
    g = [str(v) for row in speckle.GRADIENT for v in row]
    for size, goal in ((1024, ">= 50x"), (512, ">= 10x")):
        pair = work / f"speckle{size}"
        if not (pair / "def.png").exists():
            subprocess.run([sys.executable, HERE / "speckle.py", str(size), pair], check=True)
        c = str(size / 2)
        # The same ROI for both: muDIC cannot mesh up to the image's edge (its reference
        # sampling indexes past the last pixel), so both leave a margin of two elements.
        m, w = 32, size - 64
        roi = f"{m},{m},{w}x{w}"
        p = subprocess.run([python, script, pair / "ref.png", pair / "def.png", str(m), str(m), str(w), str(w),
                            "16", *shift, *g, c, c], capture_output=True, text=True, timeout=3600)
        if p.returncode != 0:
            log(f"  muDIC {size}^2 failed: {p.stderr[-2000:]}")
            continue
        mu = json.loads(p.stdout.strip().splitlines()[-1])
        v = subprocess.run([python, "-c", "import importlib.metadata as m; print(m.version('muDIC'))"],
                           capture_output=True, text=True)
        mu["version"] = v.stdout.strip()
        log(f"  muDIC {size}^2: {mu}")

        def one(label, binary, k):
            out = work / f"mudic{size}_{label}"
            shutil.rmtree(out, ignore_errors=True)
            t = timed([binary, "dic", pair / "ref.png", pair / "def.png", "--roi", roi, "--out", out, "-q"], work, 600)
            return {"wall": t["wall"], "error": nodal_error(out / "nodes.csv", size)}

        res = interleaved(binaries, runs, one)
        cell = {}
        for label, rs in res.items():
            walls = [r["wall"] for r in rs]
            errs = [r["error"] for r in rs if r["error"] is not None]
            cell[label] = (f"{spread([mu['wall_s'] / w for w in walls], '{:.0f}x')}; femu {spread(walls, '{:.2f}')} s, "
                           f"muDIC {mu['wall_s']:.1f} s; nodal RMS error femu "
                           f"{(max(errs) if errs else float('nan')):.4f} px, muDIC {mu['rms_error_px']:.4f} px")
        rows.append((f"`femu dic` {size}x{size} speckle pair, ROI {roi}, against muDIC {mu.get('version', '')}: "
                     "muDIC time / femu time",
                     goal, cell))
    return rows


def nodal_error(nodes_csv, size):
    """RMS over the nodes and the two components of femu dic's nodes.csv of the error against
    speckle.py's field (as mudic_bench.py reports muDIC's)."""
    try:
        lines = [l for l in Path(nodes_csv).read_text().splitlines() if l and not l.startswith("#")]
    except OSError:
        return None
    head = lines[0].split(",")
    ix = [head.index(k) for k in ("x_px", "y_px", "ux_px", "uy_px")]
    s = 0.0
    for line in lines[1:]:
        x, y, ux, uy = (float(line.split(",")[i]) for i in ix)
        tx, ty = speckle.known_field(x, y, size)
        s += (ux - tx) ** 2 + (uy - ty) ** 2
    return (s / (2 * (len(lines) - 1))) ** 0.5


def figure_idic(binaries, runs, work):
    study_dir = work / "idic"
    study_dir.mkdir(parents=True, exist_ok=True)
    (study_dir / "study.toml").write_text(IDIC_STUDY)

    def one(label, binary, k):
        out = study_dir / f"out_{label}"
        shutil.rmtree(out, ignore_errors=True)
        t = timed([binary, "run", "study.toml", "--out", out, "-q"], study_dir, 3600)
        try:
            s = json.loads((out / "identify/grouped/summary.json").read_text())
            idic = s["wall_time_s"]
        except (OSError, KeyError, ValueError):
            idic = None
        log(f"  integrated DIC {label}: identification {idic} s, whole run {t['wall']:.1f} s")
        return {"idic": idic, "wall": t["wall"]}

    res = interleaved(binaries, runs, one)
    cell = {
        label: spread([r["idic"] for r in rs], "{:.1f}")
        + f" s; whole `femu run` {spread([r['wall'] for r in rs], '{:.1f}')} s"
        for label, rs in res.items()
    }
    return [("integrated DIC, one realization at 4 000 elements (identification step)", "<= 10 s", cell)]


def figure_demo(binaries, runs, work, full):
    args = ["demo", "--full"] if full else ["demo"]
    name = "demo_full" if full else "demo"

    def one(label, binary, k):
        out = work / f"{name}_{label}"
        shutil.rmtree(out, ignore_errors=True)
        t = timed([binary, *args, "--out", out, "-q"], work, 3600)
        log(f"  {' '.join(args)} {label}: {t['wall']:.1f} s, {t['rss_mb']:.0f} MB")
        return t

    res = interleaved(binaries, runs, one)
    rows = [
        (
            f"`femu {' '.join(args)}` wall time",
            "<= 15 s" if full else "<= 8 s",
            {label: spread([r["wall"] for r in rs], "{:.1f}") + " s" for label, rs in res.items()},
        )
    ]
    if full:
        rows.append(
            (
                "`femu demo --full` peak memory (max RSS)",
                "<= 400 MB",
                {label: spread([r["rss_mb"] for r in rs], "{:.0f}") + " MB" for label, rs in res.items()},
            )
        )
    return rows


def figure_bench(binaries, runs, work, repeat):
    def one(label, binary, k):
        out = work / f"bench_{label}"
        shutil.rmtree(out, ignore_errors=True)
        timed([binary, "bench", "--repeat", str(repeat), "--out", out, "-q"], work, 3600)
        try:
            s = json.loads((out / "summary.json").read_text())
        except (OSError, ValueError):
            return None
        r = {
            "median": s.get("speedup_median_wall"),
            "best": s.get("speedup_wall"),
            "femu": statistics.median(s["femu_wall_s"]),
            "ccx": statistics.median(s["ccx_wall_s"]) if s.get("ccx_wall_s") else None,
        }
        log(f"  bench {label}: ccx/femu median {r['median']}, best {r['best']}; femu {r['femu']:.3f} s, ccx {r['ccx']}")
        return r

    res = interleaved(binaries, runs, one)
    cell = {}
    for label, rs in res.items():
        rs = [r for r in rs if r]
        cell[label] = (
            f"{spread([r['median'] for r in rs], '{:.1f}x')} (best-time ratio "
            f"{spread([r['best'] for r in rs], '{:.1f}x')}); femu {spread([r['femu'] for r in rs], '{:.3f}')} s, "
            f"ccx {spread([r['ccx'] for r in rs], '{:.2f}')} s"
        )
    rows = [("forward solve, paper-scale contention (`femu bench`): CalculiX time / femu time", ">= 50x", cell)]

    # The same deck solved by both binaries in turn (femu only), for a direct comparison.
    deck = next((work / f"bench_{label}" / "model.inp" for label in binaries), None)
    if deck and deck.exists():
        def solve(label, binary, k):
            out = work / f"solve_{label}"
            return timed([binary, "solve", deck, "--out", out, "--quiet", "--no-figures"], work, 600)["wall"]

        walls = interleaved(binaries, max(5, runs * 3), solve)
        rows.append(
            (
                "`femu solve` of that deck, whole command",
                "-",
                {label: spread(w, "{:.3f}") + " s" for label, w in walls.items()},
            )
        )
    return rows


def build_prev(commit: str, dest: Path) -> None:
    tree, target = Path("/tmp/prev"), Path("/tmp/prev_target")
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=ROOT, check=True)
    subprocess.run(
        ["cargo", "build", "--release", "--bin", "femu", "--target-dir", str(target)], cwd=tree, check=True
    )
    shutil.copy2(target / "release/femu", dest)


def machine() -> str:
    cpu = ""
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        m = re.search(r"Model name:\s*(.+)", out)
        cpu = m.group(1).strip() if m else ""
    except OSError:
        pass
    return f"{os.cpu_count()} cores (nproc {subprocess.run(['nproc'], capture_output=True, text=True).stdout.strip()}), {cpu}, {platform.system()} {platform.release()}"


def git(*args) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--prev", type=Path, default=Path("/tmp/femu_prev"))
    ap.add_argument("--prev-commit", default="d9ac6d3")
    ap.add_argument("--cur", type=Path, default=ROOT / "target/release/femu")
    ap.add_argument("--cur-commit", default="",
                    help="the commit --cur was built from, when it is not this checkout's target/release/femu")
    ap.add_argument("--no-build", action="store_true", help="use --cur as it is")
    ap.add_argument("--runs", type=int, default=3, help="runs of each binary for the short figures")
    ap.add_argument("--slow-runs", type=int, default=1, help="runs of each binary for idic and demo --full")
    ap.add_argument("--bench-repeat", type=int, default=5, help="femu bench --repeat")
    ap.add_argument("--only", default="dic1024,dic512,mudic,idic,demo,full,bench")
    ap.add_argument("--mudic-python", help="a Python with muDIC installed, for the mudic figure")
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "femu_perf")
    ap.add_argument("--out", type=Path, default=HERE / "results.md")
    ap.add_argument("--results", type=Path, default=HERE / "results",
                    help="folder for results.json and provenance.json (the guide's page is made from them)")
    a = ap.parse_args()
    load = os.getloadavg()[0]
    started = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")

    if not a.prev.exists():
        log(f"building the previous binary ({a.prev_commit}) into {a.prev}")
        build_prev(a.prev_commit, a.prev)
    if not a.no_build and a.cur == ROOT / "target/release/femu":
        subprocess.run(["cargo", "build", "--release", "--bin", "femu"], cwd=ROOT, check=True)
    # Copies: a build by someone else during the run must not change the binaries measured.
    a.work.mkdir(parents=True, exist_ok=True)
    binaries = {}
    for label, src in (("previous", a.prev), ("current", a.cur)):
        dst = a.work / f"femu_{label}"
        shutil.copy2(src, dst)
        binaries[label] = dst.resolve()

    only = set(a.only.split(","))
    rows = []
    if "dic1024" in only:
        log("femu dic 1024 x 1024")
        rows += figure_dic(binaries, a.runs, a.work, 1024)
    if "dic512" in only:
        log("femu dic 512 x 512")
        rows += figure_dic(binaries, a.runs, a.work, 512)
    if "mudic" in only:
        if a.mudic_python:
            log("femu dic against muDIC")
            rows += figure_mudic(binaries, a.runs, a.work, a.mudic_python)
        else:
            log("mudic: skipped (no --mudic-python)")
    if "idic" in only:
        log("integrated DIC, 4 000 elements")
        rows += figure_idic(binaries, a.slow_runs, a.work)
    if "demo" in only:
        log("femu demo")
        rows += figure_demo(binaries, a.runs, a.work, False)
    if "full" in only:
        log("femu demo --full")
        rows += figure_demo(binaries, a.slow_runs, a.work, True)
    if "bench" in only:
        log("femu bench")
        rows += figure_bench(binaries, a.runs, a.work, a.bench_repeat)

    commit = git("rev-parse", "--short", "HEAD")
    dirty = " (with uncommitted changes)" if git("status", "--porcelain", "--untracked-files=no") else ""
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    # The commit the current binary was built from: this checkout's, or --cur-commit's.
    cur_commit = commit + dirty if a.cur == ROOT / "target/release/femu" or not a.cur_commit else a.cur_commit
    lines = [
        "# Performance figures",
        "",
        f"- date: {now}",
        f"- machine: {machine()}",
        f"- current: `{a.cur}` built from commit {cur_commit}",
        f"- previous: `{a.prev}` (commit {a.prev_commit})",
        f"- method: `python3 bench/perf/run.py {' '.join(sys.argv[1:])}`; the two binaries run in turn "
        f"({a.runs} runs each, {a.slow_runs} for the integrated DIC and `demo --full`); "
        "median (min-max); wall times and peak memory from /usr/bin/time -v",
        "",
        "| figure | goal | previous | current |",
        "|---|---|---|---|",
    ]
    for fig, goal, cell in rows:
        lines.append(f"| {fig} | {goal} | {cell.get('previous', 'n/a')} | {cell.get('current', 'n/a')} |")
    text = "\n".join(lines) + "\n"
    print(text)
    a.out.write_text(text)
    log(f"written {a.out}")
    a.results.mkdir(parents=True, exist_ok=True)
    (a.results / "results.json").write_text(json.dumps({
        "previous": {"binary": str(a.prev), "commit": a.prev_commit},
        "current": {"binary": str(a.cur), "commit": cur_commit},
        "runs": a.runs, "slow_runs": a.slow_runs, "bench_repeat": a.bench_repeat,
        "rows": [{"figure": fig, "goal": goal, "previous": cell.get("previous"),
                  "current": cell.get("current")} for fig, goal, cell in rows],
    }, indent=1) + "\n")
    (a.results / "provenance.json").write_text(json.dumps({
        "date": started, "machine": machine(), "commit": cur_commit, "build": "release builds",
        "load": f"{load:.1f}", "command": "python3 bench/perf/run.py " + shlex.join(sys.argv[1:]),
    }, indent=1) + "\n")
    log(f"written {a.results}/results.json and provenance.json")


if __name__ == "__main__":
    main()
