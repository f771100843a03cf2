#!/usr/bin/env python3
"""Markdown tables of measured runs, each headed by its provenance (date, machine, commit).

    python3 scripts/guide/tables.py demo RUN_DIR            # `femu demo` / `femu run` folder
    python3 scripts/guide/tables.py convergence RUN_DIR     # `femu convergence` folder
    python3 scripts/guide/tables.py bench RUN_DIR           # `femu bench` folder
    python3 scripts/guide/tables.py page DEMO CONV [BENCH] > docs/guide/src/measured/runs.md

Every number comes from the run's own output files (`summary.json`, `steps.json`,
`convergence.csv`); nothing is typed in. The provenance comes from `provenance.json` in the run
folder, which `scripts/guide/measure.sh` writes when it starts the run (date, machine, commit
of the binary's sources, load average); without it the table says what is unknown.
"""

import csv
import json
import pathlib
import sys


def provenance(run):
    p = pathlib.Path(run) / "provenance.json"
    if p.exists():
        d = json.loads(p.read_text())
    else:
        d = {}
    return (
        f"*Measured {d.get('date', 'on an unrecorded date')} on {d.get('machine', 'an unrecorded machine')}, "
        f"commit {d.get('commit', 'unrecorded')}, {d.get('build', 'build unrecorded')}; "
        f"load average {d.get('load', 'unrecorded')} at the start; "
        f"command `{d.get('command', '?')}`.*\n"
    )


def pct(x):
    return "–" if x is None else f"{100 * x:+.3g} %"


def demo(run):
    run = pathlib.Path(run)
    s = json.loads((run / "summary.json").read_text())
    out = [provenance(run)]
    out.append("\n**Steps** (wall time of each step, from `steps.json`):\n")
    out.append("| step | status | seconds |\n|---|---|---|")
    steps = s["run"]["steps"]
    for st in steps:
        out.append(f"| {st['name']} | {st['status']} | {st['seconds']:.2f} |")
    out.append(f"| whole run | | {s['run'].get('total_seconds', float('nan')):.2f} |")
    model = s.get("model", {})
    out.append(
        f"\nModel: {model.get('elements', '?')} {model.get('element', '')} elements, "
        f"{s['run'].get('threads', '?')} threads.\n"
    )
    for grouping, ident in s.get("identification", {}).items():
        out.append(
            f"\n**Identification, {grouping}** ({ident.get('optimizer', '?')}, forward solves per "
            f"start {ident.get('forward_solves_per_start')}, {ident.get('wall_time_s', 0):.1f} s): "
            "identified against the reference, relative error (the seed's Eq. 4) and predicted "
            "relative sd.\n"
        )
        out.append("| parameter | reference | identified | error | predicted sd |\n|---|---|---|---|---|")
        units = {p["name"]: (p["unit"], p["unit_factor"]) for p in ident.get("free_parameters", [])}
        for p in ident["parameters"]:
            unit, f = units.get(p["name"], ("", 1.0))
            ref = p.get("reference")
            ref = "–" if ref is None else f"{ref * f:.4g} {unit}"
            sd = p.get("relative_sd")
            sd = "–" if sd is None else f"{100 * sd:.3g} %"
            out.append(
                f"| {p['name']} | {ref} | {p['identified'] * f:.4g} {unit} | "
                f"{pct(p.get('relative_error'))} | {sd} |"
            )
        if ident.get("discretization"):
            out.append(f"\nDiscretization check: {ident['discretization'].rstrip('.')}.")
    return "\n".join(out) + "\n"


def convergence(run):
    run = pathlib.Path(run)
    rows = list(csv.DictReader(open(run / "convergence.csv")))
    s = json.loads((run / "summary.json").read_text())
    out = [provenance(run)]
    out.append(
        f"\nThe {rows[0]['test']} test on a sequence of meshes of the built-in thigh, each "
        "compared with the finest of its element type at the DIC grid points (`convergence.csv`; "
        "the finest mesh of each type is the reference, so its difference is 0):\n"
    )
    out.append("| element | elements | largest difference (mm) | RMS difference (mm) | solve (s) |")
    out.append("|---|---|---|---|---|")
    for r in rows:
        if float(r["d_scale"]) != 1.0 or r["status"] != "converged":
            continue
        out.append(
            f"| {r['element']} | {r['elements']} | {float(r['max_diff_mm']):.2e} | "
            f"{float(r['rms_diff_mm']):.2e} | {float(r['solve_s']):.3f} |"
        )
    out.append("\nFitted rates (log-log, difference against element size):\n")
    out.append("| element | rate, largest difference | rate, RMS difference |\n|---|---|---|")
    for e in s.get("per_element", []):
        if e.get("d_scale", 1.0) != 1.0:
            continue
        rm, rr = e.get("rate_max") or {}, e.get("rate_rms") or {}
        if not rm and not rr:
            continue
        fmt = lambda d: "–" if not d else f"{d['rate']:.2f} (r² {d['r_squared']:.3f})"
        out.append(f"| {e['element']} | {fmt(rm)} | {fmt(rr)} |")
    lk = s.get("locking") or {}
    if lk.get("sentence"):
        out.append(f"\n{lk['sentence']}")
    if s.get("recommendation"):
        out.append(f"\nRecommendation: {s['recommendation']}")
    out.append(f"\nWhole study: {s.get('total_s', float('nan')):.1f} s.")
    return "\n".join(out) + "\n"


def bench(run):
    run = pathlib.Path(run)
    s = json.loads((run / "summary.json").read_text())
    out = [provenance(run)]
    out.append(
        f"\nThe paper-scale contention deck ({s['elements']} CPE4, {s['nodes']} nodes), whole "
        f"commands from deck to result files, {s['repeat']} runs each, alternated, {s['threads']} "
        "threads:\n"
    )
    out.append("| | femu | CalculiX |\n|---|---|---|")

    def med(v):
        v = sorted(v)
        return v[len(v) // 2] if v else float("nan")

    ccx_best = s.get("ccx_best_wall_s")
    ccx_best = "–" if ccx_best is None else f"{ccx_best:.3f} s"
    ccx_med = "–" if not s.get("ccx_wall_s") else f"{med(s['ccx_wall_s']):.3f} s"
    out.append(f"| best wall time | {s['femu_best_wall_s']:.3f} s | {ccx_best} |")
    out.append(f"| median wall time | {med(s['femu_wall_s']):.3f} s | {ccx_med} |")
    if s.get("speedup_wall") is not None:
        out.append(f"| ratio CalculiX / femu, best / median | {s['speedup_wall']:.1f}x / "
                   f"{s['speedup_median_wall']:.1f}x | |")
    if s.get("max_displacement_difference_ratio") is not None:
        out.append(f"| largest nodal difference / largest displacement | "
                   f"{s['max_displacement_difference_ratio']:.2e} | |")
    if s.get("femu_peak_memory_mb") is not None:
        out.append(f"| femu's peak memory | {s['femu_peak_memory_mb']:.0f} MB | |")
    out.append(
        f"\nThe compression test on the same mesh (in process, setup and solve): best "
        f"{s['compression_best_s']:.2f} s, {s['compression_increments']} increments, "
        f"{s['compression_newton_iterations']} Newton iterations."
    )
    return "\n".join(out) + "\n"


def page(demo_dir, conv_dir, bench_dir=None):
    parts = [
        "# Runs of this release\n\n"
        "<!-- Written by scripts/guide/tables.py from measured run folders: do not edit. "
        "Regenerate with\n     bash scripts/guide/measure.sh target/release/femu -->\n\n"
        "These tables are produced by `scripts/guide/tables.py` from the output folders of runs "
        "made by `scripts/guide/measure.sh` (see [How the numbers are made](index.md)); each "
        "says when, where and with which commit it was measured.\n",
        "\n## `femu demo`\n\n" + demo(demo_dir),
        "\n## `femu convergence`\n\n" + convergence(conv_dir),
    ]
    if bench_dir:
        parts.append("\n## `femu bench`: femu against CalculiX\n\n" + bench(bench_dir))
    return "".join(parts)


def main(argv):
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    kind, args = argv[1], argv[2:]
    fn = {"demo": demo, "convergence": convergence, "bench": bench, "page": page}.get(kind)
    if fn is None:
        print(f"unknown table {kind!r}", file=sys.stderr)
        return 2
    sys.stdout.write(fn(*args))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
