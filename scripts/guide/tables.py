#!/usr/bin/env python3
"""Markdown tables of measured runs, each headed by its provenance (date, machine, commit).

    python3 scripts/guide/tables.py demo RUN_DIR            # `femu demo` / `femu run` folder
    python3 scripts/guide/tables.py convergence RUN_DIR     # `femu convergence` folder
    python3 scripts/guide/tables.py bench RUN_DIR           # `femu bench` folder
    python3 scripts/guide/tables.py page DEMO CONV [BENCH]  # the runs page from run folders
    python3 scripts/guide/tables.py runs RESULTS > docs/guide/src/measured/runs.md  # from measure.sh's kept files
    python3 scripts/guide/tables.py verification RESULTS    # values the tests recorded
    python3 scripts/guide/tables.py render TEMPLATE         # a page of scripts/guide/templates/
    python3 scripts/guide/tables.py check                   # the generated pages up to date?

Every number comes from the run's own output files (`summary.json`, `steps.json`,
`convergence.csv`); nothing is typed in. The provenance comes from `provenance.json` in the run
folder, which `scripts/guide/measure.sh` writes when it starts the run (date, machine, commit
of the binary's sources, load average); without it the table says what is unknown.
"""

import csv
import difflib
import json
import math
import pathlib
import re
import statistics
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
TEMPLATES = ROOT / "scripts" / "guide" / "templates"


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
        f"command `{d.get('command', '?')}`.*"
        + (f" {d['note']}" if d.get("note") else "")
        + "\n"
    )


def pct(x):
    return "–" if x is None else f"{100 * x:+.3g} %"


def two_digits(v):
    """A mean |error| in % to two significant digits, written out (234, not 2.3e+02) from 100."""
    return f"{v:.2g}" if v < 100 else f"{v:.0f}"


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


def runs(results):
    """The page of measure.sh's runs from the files it keeps in `results` (demo/,
    convergence/ and, when CalculiX was installed, bench/)."""
    d = ROOT / results
    bench_dir = d / "bench"
    return page(d / "demo", d / "convergence", bench_dir if bench_dir.exists() else None)


def number(v):
    """A measured value for a table: integers as such, the rest with three significant digits."""
    if v is None:
        return "–"
    if float(v).is_integer() and abs(v) < 1e7:
        return f"{int(v)}"
    t = f"{v:.3g}"
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m.group(1) == "-" else "") + m.group(2), t)


def verification_table(results, name, prov, targets):
    """The values one test target recorded (RESULTS/NAME.jsonl), in the order of the tests in
    its source file, headed by the provenance and the command that measures them again."""
    path = pathlib.Path(results) / f"{name}.jsonl"
    crate, test = name.split("-", 2)[0] + "-" + name.split("-", 2)[1], name.split("-", 2)[2]
    target = targets.get((crate, test))
    command = f"cargo test --release -p {crate} " + ("--lib" if test == "lib" else f"--test {test}")
    # A target measured on its own (`verify.sh --only`) carries its own date, machine, commit.
    prov = {**prov, **{k: target[k] for k in ("date", "machine", "commit") if target and k in target}}
    head = (
        f"*Measured {prov.get('date', 'on an unrecorded date')} on "
        f"{prov.get('machine', 'an unrecorded machine')}, commit {prov.get('commit', 'unrecorded')}; "
        f"`{command}`"
        + (
            f", tests {target['test_seconds']:.1f} s" if target and target.get("test_seconds") is not None
            else f", {target['seconds']:.0f} s of `cargo test`, any rebuild included" if target else ""
        )
        + ".*\n"
    )
    if not path.exists():
        return head + "\nNothing recorded: the tests skipped (see above for what they need).\n"
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    source = ROOT / "crates" / crate / "tests" / f"{test}.rs"
    if test == "lib":
        # Unit tests: in the order of the crate's sources, file by file.
        text = "".join(f.read_text() for f in sorted((ROOT / "crates" / crate / "src").rglob("*.rs")))
    else:
        text = source.read_text() if source.exists() else ""

    def where(r):
        i = text.find(f"fn {r['test'].split('::')[-1]}(")
        return i if i >= 0 else len(text)

    rows = sorted(enumerate(rows), key=lambda ir: (where(ir[1]), ir[0]))
    out = [head, "| check | value | bound asserted | test |", "|---|---|---|---|"]
    for _, r in rows:
        unit = f" {r['unit']}" if r.get("unit") else ""
        value = number(r["value"]) + (unit if r["value"] is not None else "")
        cell = lambda t: t.replace("|", "\\|")
        out.append(f"| {cell(r['quantity'])} | {value} | {cell(r['bound'])} | `{r['test']}` |")
    return "\n".join(out) + "\n"


def verification(results):
    """docs/guide/src/measured/verification.md from its template and RESULTS (verify.sh)."""
    results = pathlib.Path(results)
    prov = json.loads((results / "provenance.json").read_text())
    targets = {}
    if (results / "targets.json").exists():
        for t in json.loads((results / "targets.json").read_text()):
            targets[(t["crate"], t["test"])] = t
    page = (TEMPLATES / "verification.md").read_text()
    total = sum(t.get("test_seconds") or t["seconds"] for t in targets.values())
    # The runs of verify.sh the tables come from: one for a full rerun, more when targets were
    # measured again on their own (`--only`): grouped by machine and commit, each with the dates
    # and load averages at which its targets started.
    runs = {}
    for t in targets.values():
        runs.setdefault((t.get("machine", prov.get("machine", "?")), t.get("commit", prov.get("commit", "?"))), []).append(t)
    if len(runs) <= 1:
        summary = (
            f"*All the tables: measured {prov.get('date', '?')} on {prov.get('machine', '?')}, commit "
            f"{prov.get('commit', '?')}, {prov.get('build', '?')}, load average {prov.get('load', '?')} "
            f"at the start; {len(targets)} test targets, {total / 60:.0f} min; "
            f"command `bash scripts/guide/verify.sh`.*"
        )
    else:
        def span(values):
            values = sorted(set(values))
            return values[0] if len(values) == 1 else f"{values[0]} to {values[-1]}"

        parts = []
        for (machine, commit), ts in sorted(runs.items(), key=lambda kv: min(t.get("date", prov.get("date", "")) for t in kv[1])):
            dates = span([t.get("date", prov.get("date", "?")) for t in ts])
            loads = span([float(t.get("load", prov.get("load", "nan"))) for t in ts])
            seconds = sum(t.get("test_seconds") or t["seconds"] for t in ts)
            took = f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min"
            parts.append(
                f"{len(ts)} target{'s' if len(ts) > 1 else ''} measured {dates} on {machine}, commit "
                f"{commit}, load average {loads} at their start, {took}"
            )
        summary = (
            f"*The tables come from {len(runs)} runs of `bash scripts/guide/verify.sh`, "
            f"{prov.get('build', '?')}; each table gives its own date and commit: "
            + "; ".join(parts) + ".*"
        )
    page = page.replace("{{summary}}", summary)
    return re.sub(
        r"\{\{table ([\w-]+)\}\}",
        lambda m: verification_table(results, m.group(1), prov, targets).rstrip("\n"),
        page,
    )


UNDER_PROBE = ["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"]


def dic_campaign(pymust_dir, own_dir):
    """The recorded-frame route on simulated B-mode sequences (bench/independent_us/campaign.py):
    per renderer and route, each parameter's mean / largest |error| and how many of its 95 %
    intervals hold the truth, from the campaign.csv and fields.csv kept in the repository
    (the pymust rows from PYMUST_DIR, femu's own from OWN_DIR)."""
    out = []
    body = []
    for label, d, renderer in [
        ("pymust (independent: simulated RF of a linear array, delay-and-sum; `bench/independent_us/`)",
         pymust_dir, "pymust"),
        ("femu's own (`femu us-sim`, 5 % of the scatterers renewed per step)", own_dir, "femu"),
    ]:
        d = ROOT / d
        rows = [r for r in csv.DictReader(open(d / "campaign.csv")) if r["renderer"] == renderer]
        fields = [f for f in csv.DictReader(open(d / "fields.csv")) if f["renderer"] == renderer]
        out.append(f"- {label}: " + provenance(d).strip())
        ok = [f for f in fields if f["dic"] == "ok"]
        ux = [float(f["rms_ux_px"]) for f in ok]
        uy = [float(f["rms_uy_px"]) for f in ok]
        seeds = sorted({int(r["seed"]) for r in rows})
        first = True
        for route in ("plain", "weighted"):
            cells, covered, total = [], 0, 0
            for par in UNDER_PROBE:
                rr = [r for r in rows if r["route"] == route and r["parameter"] == par]
                e = [abs(float(r["error_pct"])) for r in rr]
                c = sum(int(r["covered"]) for r in rr)
                covered, total = covered + c, total + len(rr)
                cells.append(f"{sum(e) / len(e):.2g} / {max(e):.2g} %, {c}/{len(rr)}" if e else "–")
            head = (
                f"{label}, seeds {seeds[0]}–{seeds[-1]} | {len(ok)} of {len(fields)} | "
                f"{sum(ux) / len(ux):.2f} ({max(ux):.2f}) / {sum(uy) / len(uy):.2f} ({max(uy):.2f})"
                if first else " | | "
            )
            body.append(f"| {head} | {route} | " + " | ".join(cells) + f" | {covered}/{total} |")
            first = False
    out.append("")
    out.append("| frames | sequences converged | composed RMS, lateral / axial (px), mean (max) | route | "
               + " | ".join(UNDER_PROBE) + " | truths covered |")
    out.append("|---|---|---|---|" + "---|" * len(UNDER_PROBE) + "---|")
    out += body
    return "\n".join(out) + "\n"


def idic_campaign(run_dir):
    """Integrated DIC on the pymust sequences (bench/independent_us/idic_campaign.py), from the
    idic_campaign.csv kept in the repository: per parameter under the probe, the integrated
    route's mean and largest |error|, mean error, the 95 % intervals that hold the truth and the
    seeds they miss; beside it the DIC → FEMU routes on the same frames (weighted and plain,
    rows `dic-weighted` and `dic-plain` when the file has them)."""
    d = ROOT / run_dir
    all_rows = list(csv.DictReader(open(d / "idic_campaign.csv")))
    route = lambda r: r.get("route", "integrated")
    rows = [r for r in all_rows if route(r) == "integrated"]
    others = [(k, t) for k, t in (("dic-weighted", "weighted DIC → FEMU"), ("dic-plain", "plain DIC → FEMU"))
              if any(route(r) == k for r in all_rows)]
    out = [provenance(d).strip(), ""]
    out.append("| parameter | mean / max \\|error\\| | mean error | 95 % intervals holding the truth |"
               + "".join(f" {t}: mean / max \\|error\\|, intervals |" for _, t in others))
    out.append("|---|---|---|---|" + "---|" * len(others))
    for par in UNDER_PROBE:
        rr = [r for r in rows if r["parameter"] == par]
        e = [100 * float(r["relative_error"]) for r in rr]
        missed = [r["seed"] for r in rr if r["covered"] != "1"]
        held = f"{len(rr) - len(missed)} of {len(rr)}" + (
            f" (missed: seed{'s' if len(missed) > 1 else ''} {', '.join(missed)})" if missed else "")
        mean = sum(e) / len(e)
        cells = []
        for k, _ in others:
            ro = [r for r in all_rows if route(r) == k and r["parameter"] == par]
            eo = [100 * abs(float(r["relative_error"])) for r in ro]
            cov = sum(r["covered"] == "1" and not on_bound(float(r["relative_error"])) for r in ro)
            cells.append(f" {sum(eo) / len(eo):.3g} / {max(eo):.3g} %, {cov} of {len(ro)} |")
        out.append(
            f"| {par} | {sum(map(abs, e)) / len(e):.3g} / {max(map(abs, e)):.3g} % | "
            f"{'+' if mean >= 0 else '−'}{abs(mean):.3g} % | {held} |" + "".join(cells)
        )
    wall = [float(r["wall_s"]) for r in rows]
    out.append(f"\n{min(wall):.0f}–{max(wall):.0f} s per realization for the integrated DIC (`wall_s`), "
               f"{len({r['seed'] for r in rows})} realizations.")
    return "\n".join(out) + "\n"


def performance(results):
    """The table of bench/perf/run.py (results.json), headed by its provenance."""
    d = ROOT / results
    r = json.loads((d / "results.json").read_text())
    prev, cur = r["previous"], r["current"]
    out = [provenance(d).strip(), ""]
    out.append(
        f"Previous: a release build of commit {prev['commit']}; current: {cur['commit']}. The two "
        f"binaries run in turn, {r['runs']} runs each"
        + (f" ({r['slow_runs']} for the integrated DIC and `demo --full`)"
           if any("integrated DIC" in x["figure"] or "--full" in x["figure"] for x in r["rows"]) else "")
        + (f", `femu bench --repeat {r['bench_repeat']}`" if any("femu bench" in x["figure"] for x in r["rows"]) else "")
        + "; median (min–max).\n"
    )
    out.append("| figure | goal | previous | current |\n|---|---|---|---|")
    for row in r["rows"]:
        out.append(f"| {row['figure']} | {row['goal']} | {row['previous'] or 'n/a'} | {row['current'] or 'n/a'} |")
    return "\n".join(out) + "\n"


def contact(results):
    """The rigid-body contact tests (bench/contact/run.py's contact.csv), headed by its
    provenance."""
    d = ROOT / results
    rows = list(csv.DictReader(open(d / "contact.csv")))
    out = [provenance(d).strip(), ""]
    out.append("| test | elements | Newton iterations (increments, cut-backs) | solve (s), median (min–max) "
               "| whole process CPU (s) | peak memory (MiB) | off the tight solve | plate/indenter travel (mm) |")
    out.append("|---|---|---|---|---|---|---|---|")
    for r in rows:
        elements = f"{int(r['elements']):,}".replace(",", " ")
        out.append(
            f"| {r['test']} | {elements} | {r['iterations']} ({r['increments']}, {r['cutbacks']}) "
            f"| {r['solve_s_median']} ({r['solve_s_min']}–{r['solve_s_max']}) | {r['process_cpu_s_median']} "
            f"| {r['peak_mib_median']} "
            f"| {float(r['difference_from_tight']):.1e} | {r['travel_mm']} |"
        )
    out.append(f"\n{rows[0]['runs']} runs of each case with the default settings.")
    return "\n".join(out) + "\n"


def recorded_rows(name, key):
    """The rows of bench/verification/results/NAME.jsonl whose quantity holds KEY (underscores
    for spaces); an error naming the file and key when none does."""
    path = ROOT / "bench" / "verification" / "results" / f"{name}.jsonl"
    text = key.replace("_", " ")
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = [r for r in rows if text in r["quantity"]]
    if not rows:
        raise SystemExit(f"{path}: no recorded quantity holds {text!r}")
    return rows


def recorded_format(v, fmt):
    return f"{100 * v:.0f}" if fmt == "pct" else f"{v:{fmt}}"


def recorded(name, key, fmt=".2f"):
    """One value a verification test recorded (`verify.sh`), for a sentence of a page:
    `{{recorded NAME KEY [FORMAT]}}`, KEY a part of the quantity (underscores for spaces), which
    must name one quantity; FORMAT a Python format spec or `pct` (x 100, no decimals)."""
    rows = recorded_rows(name, key)
    if len(rows) != 1:
        raise SystemExit(f"{name}.jsonl: {len(rows)} recorded quantities hold {key.replace('_', ' ')!r}, not one")
    return recorded_format(rows[0]["value"], fmt)


def recorded_span(name, key, fmt=".2f"):
    """The smallest and largest of the values whose quantity holds KEY: `low–high`."""
    values = [r["value"] for r in recorded_rows(name, key)]
    low, high = recorded_format(min(values), fmt), recorded_format(max(values), fmt)
    return low if low == high else f"{low}–{high}"


def recorded_provenance(*names):
    """When, where and at which commit the verification targets NAME... were measured (their
    entries in bench/verification/results/targets.json, else its provenance.json)."""
    d = ROOT / "bench" / "verification" / "results"
    prov = json.loads((d / "provenance.json").read_text())
    targets = {f"{t['crate']}-{t['test']}": t for t in json.loads((d / "targets.json").read_text())}
    seen = []
    for n in names:
        t = targets.get(n)
        if t is None:
            raise SystemExit(f"{d / 'targets.json'}: no target {n}")
        what = (t.get("date", prov.get("date", "?")), t.get("machine", prov.get("machine", "?")),
                t.get("commit", prov.get("commit", "?")))
        if what not in seen:
            seen.append(what)
    return "; ".join(f"measured {date} on {machine}, commit {commit}" for date, machine, commit in seen)


def rows_where(path, **equal):
    """The rows of the CSV file PATH whose columns equal EQUAL (`column=value`), at least one."""
    rows = [r for r in csv.DictReader(open(path)) if all(r.get(k) == v for k, v in equal.items())]
    if not rows:
        raise SystemExit(f"{path}: no rows with " + ", ".join(f"{k} {v!r}" for k, v in equal.items()))
    return rows


def dic_real_rows(results, name):
    """The checks.csv and pairs.csv of one configuration of bench/dic_real/run.sh."""
    d = ROOT / results / name
    if not d.is_dir():
        raise SystemExit(f"{ROOT / results}: no configuration {name!r} (bench/dic_real/run.sh)")
    return list(csv.DictReader(open(d / "checks.csv"))), list(csv.DictReader(open(d / "pairs.csv")))


def dic_real_find(checks, check, frames, region, points):
    """The row of CHECK over FRAMES (None: pooled over the sequence) in REGION over POINTS."""
    for r in checks:
        pooled = r["frames"].endswith("instance(s)")
        if (r["check"], r["region"], r["points_set"]) == (check, region, points) and (
                pooled if frames is None else r["frames"] == frames):
            return r
    raise SystemExit(f"dic_real: no {check} {frames} {region} ({points} points) in checks.csv")


DIC_REAL_COMPOSITION = "gastroc_jumping_048>gastroc_jumping_050>gastroc_jumping_052"


def dic_real_rms(results, name, check, region, points="trusted", what="rms_", scale="1"):
    """`(x, y)` px as configuration NAME of bench/dic_real/run.sh measured it: the RMS (WHAT
    `rms_`) or the predicted sd (`predicted_sd_`) of CHECK in REGION over POINTS (all or
    trusted), times SCALE. CHECK: `forward-backward` or `composition`, pooled over the sequence,
    or `composition@NNN`, the composition from frame NNN two frames on against the one through
    the frame between (`composition@048`: 048→052 against 048→050→052)."""
    checks, _ = dic_real_rows(results, name)
    if "@" in check:
        check, first = check.split("@")
        n = int(first)
        frames = ">".join(f"gastroc_jumping_{k:03d}" for k in (n, n + 2, n + 4))
    else:
        frames = None
    r = dic_real_find(checks, check, frames, region, points)
    k = float(scale)
    if what == "predicted_sd_":
        x, y = float(r["predicted_sd_x_px"]), float(r["predicted_sd_y_px"])
    else:
        x, y = float(r["rms_dx_px"]), float(r["rms_dy_px"])
    return f"({k * x:.2f}, {k * y:.2f})"


def dic_real(results):
    """The real-frame table of bench/dic_real/run.sh: per configuration (ROI, options), the
    consecutive pairs that converged, the elements trusted, the forward–backward RMS pooled over
    the sequence and the composition 048→052 against 048→050→052, over the trusted points."""
    d = ROOT / results
    configs = list(csv.DictReader(open(d / "configs.csv")))
    out = [provenance(d).strip(), ""]
    out.append("| configuration | ROI | frames | options | consecutive pairs converged (elements trusted; iterations) "
               "| forward–backward, pooled, trusted points (px) | composition 048→052, all points (px) "
               "| composition 048→052, trusted points: all (px) | superficial | middle | deep | wall (s) |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for c in configs:
        opts = f"`{c['options']}`" if c["options"] else "defaults"
        if c.get("error"):
            out.append(f"| {c['name']} | {c['roi']} | {c['frames']} | {opts} | did not converge: "
                       f"{c['error']} | | | | | | | {float(c['wall_s']):.0f} |")
            continue
        checks, pairs = dic_real_rows(results, c["name"])
        # The frames in order (their names end in the frame number), and the pairs that go
        # from one frame to the next.
        frames = sorted({p["reference"] for p in pairs} | {p["deformed"] for p in pairs})
        consecutive = [p for p in pairs if p["deformed"] in frames[1:]
                       and frames.index(p["deformed"]) == frames.index(p["reference"]) + 1]
        conv = [p for p in consecutive if p["converged"] == "true"]
        trusted = [100 * float(p["trusted_fraction"]) for p in conv]
        span = f"{min(trusted):.0f}–{max(trusted):.0f} %" if trusted else "–"
        its = [int(p["iterations"]) for p in conv]
        its = f"{min(its)}–{max(its)}" if its else "–"

        def rms(check, region, points):
            frames = None if check == "forward-backward" else DIC_REAL_COMPOSITION
            r = dic_real_find(checks, check, frames, region, points)
            return f"({float(r['rms_dx_px']):.2f}, {float(r['rms_dy_px']):.2f})"

        out.append(
            f"| {c['name']} | {c['roi']} | {c['frames']} | {opts} "
            f"| {len(conv)} of {len(consecutive)} ({span}; {its}) | {rms('forward-backward', 'all', 'trusted')} "
            f"| {rms('composition', 'all', 'all')} | {rms('composition', 'all', 'trusted')} "
            f"| {rms('composition', 'superficial', 'trusted')} | {rms('composition', 'middle', 'trusted')} "
            f"| {rms('composition', 'deep', 'trusted')} | {float(c['wall_s']):.0f} |"
        )
    return "\n".join(out) + "\n"


def dic_real_r(results, name, first="048"):
    """How far the forward–backward check maps the composition error on the real frames: the
    correlation coefficient of |forward–backward difference| (FIRST → next → FIRST) and
    |composition difference| (FIRST → two frames on against the path through the frame between)
    at the same points of configuration NAME (its points.csv.gz): `r = R (N points)`."""
    import gzip
    path = ROOT / results / name / "points.csv.gz"
    if not path.is_file():
        raise SystemExit(f"{path}: missing (bench/dic_real/run.sh keeps it for the whole ROI)")
    n = int(first)
    fr = lambda *k: ">".join(f"gastroc_jumping_{v:03d}" for v in k)
    fb, co = {}, {}
    for r in csv.DictReader(gzip.open(path, "rt")):
        key = (r["x_px"], r["y_px"])
        mag = math.hypot(float(r["dx_px"]), float(r["dy_px"]))
        if r["check"] == "forward-backward" and r["frames"] == fr(n, n + 2, n):
            fb[key] = mag
        elif r["check"] == "composition" and r["frames"] == fr(n, n + 2, n + 4):
            co[key] = mag
    both = [k for k in co if k in fb]
    if len(both) < 3:
        raise SystemExit(f"{path}: fewer than 3 points in both checks from frame {first}")
    r = statistics.correlation([fb[k] for k in both], [co[k] for k in both])
    return f"r = {r:+.2f}".replace("+", "").replace("-", "−") + f" over {len(both)} points"


def mudic_real(run_dir, what="table", bound="5"):
    """muDIC against femu-dic on the real frames (bench/dic_real/mudic.sh's compare.json): WHAT
    `table` (per consecutive pair: nodes compared, RMS and median |difference|, the share within
    two combined sd, muDIC's time), `apart` (how many pairs differ by an RMS above BOUND px in
    either component: `N of M`) or `provenance`."""
    d = ROOT / run_dir
    if what == "provenance":
        return provenance(d).strip()
    pairs = json.load(open(d / "compare.json"))
    frames = [48, 50, 52, 54, 56, 58]
    if what == "apart":
        far = sum(max(p["rms_diff_px"]) > float(bound) for p in pairs)
        return f"{far} of {len(pairs)}"
    out = [provenance(d).strip(), ""]
    out.append("| pair | nodes compared | RMS difference (x, y) px | median \\|difference\\| (x, y) px "
               "| components within 2 combined sd | muDIC (s) |")
    out.append("|---|---|---|---|---|---|")
    for p in pairs:
        k = p["pair"]
        rx, ry = p["rms_diff_px"]
        mx, my = p["median_abs_diff_px"]
        out.append(f"| {frames[k]:03d}→{frames[k + 1]:03d} | {p['nodes']} | ({rx:.2f}, {ry:.2f}) "
                   f"| ({mx:.2f}, {my:.2f}) | {100 * p['within_2sd_combined']:.0f} % | {p['mudic_wall_s']:.1f} |")
    return "\n".join(out) + "\n"


def substitution(run_dir, variant, parameter, what="mean"):
    """bench/independent_us/substitution.py's substitution.csv: for VARIANT (`measured`,
    `true`, `true-lateral`, ...) and PARAMETER, WHAT `mean` (mean |error| %, two significant
    digits), `span` (smallest–largest |error| %), `covered` (`N of M` intervals holding the
    truth), `seeds` (how many realizations) or `provenance`."""
    d = ROOT / run_dir
    if what == "provenance":
        return provenance(d).strip()
    rows = rows_where(d / "substitution.csv", variant=variant, parameter=parameter)
    e = [abs(float(r["error_pct"])) for r in rows]
    if what == "span":
        return f"{min(e):.2g}–{max(e):.2g}"
    if what == "covered":
        return f"{sum(r['covered'] == '1' for r in rows)} of {len(rows)}"
    if what == "seeds":
        return str(len(rows))
    return f"{sum(e) / len(e):.2g}"


def substitution_table(run_dir):
    """bench/independent_us/substitution.py's substitution.csv as a table: per variant (in the
    file's order) and parameter, mean |error| % and the 95 % intervals holding the truth."""
    d = ROOT / run_dir
    rows = list(csv.DictReader(open(d / "substitution.csv")))
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    params = list(dict.fromkeys(r["parameter"] for r in rows))
    out = ["| field identified | " + " | ".join(params) + " |", "|---|" + "---|" * len(params)]
    for v in variants:
        cells = []
        for p in params:
            rr = [r for r in rows if r["variant"] == v and r["parameter"] == p]
            e = [abs(float(r["error_pct"])) for r in rr]
            cells.append(f"{sum(e) / len(e):.2g} %, {sum(r['covered'] == '1' for r in rr)} of {len(rr)}")
        out.append(f"| `{v}` | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def lateral_strain(run_dir):
    """bench/independent_us/substitution.py's lateral_strain.csv: in how many realizations the
    measured mean lateral strain of the fat layer is smaller than the true one, and by how much
    on average: `N of M realizations, by X % of the true strain on average`."""
    rows = list(csv.DictReader(open(ROOT / run_dir / "lateral_strain.csv")))
    rel = [float(r["measured"]) / float(r["true"]) - 1 for r in rows]
    small = sum(e < 0 for e in rel)
    return f"{small} of {len(rel)} realizations, by {-100 * sum(rel) / len(rel):.2g} % of the true strain on average"


def lateral_speckle(run_dir):
    """bench/independent_us/lateral_speckle.py's results.csv as a table: per point-spread
    function and motion, the speckle femu dic measured and the field's lateral and axial
    error (mean / RMS, px); then the provenance."""
    d = ROOT / run_dir
    rows = list(csv.DictReader(open(d / "results.csv")))
    motion = {"fe": "the thigh's first load step (FE), one increment",
              "fe2": "the same in two increments, composed", "PSR": "uniform strain (PSR)"}
    out = ["| PSF FWHM, lateral x axial (mm) | speckle femu dic measured (px) | motion | "
           "lateral error, mean / RMS (px) | axial error, mean / RMS (px) |",
           "|---|---|---|---|---|"]
    for r in rows:
        if r["dic"] != "ok":
            out.append(f"| {r['psf_fwhm_mm']} | – | {motion[r['motion']]} | {r['dic']} | |")
            continue
        out.append(f"| {r['psf_fwhm_mm']} | {r['speckle_fwhm_px']} | {motion[r['motion']]} | "
                   f"{float(r['lateral_mean_px']):+.2f} / {float(r['lateral_rms_px']):.2f} | "
                   f"{float(r['axial_mean_px']):+.2f} / {float(r['axial_rms_px']):.2f} |")
    return "\n".join(out) + "\n\n" + provenance(d).strip() + "\n"


def shear_correction(run_dir, what):
    """bench/independent_us's speckle-shift study (psf_phase.py, shear_correction.py): WHAT is
    `psf` (per depth, pymust's Hann-apodized PSF's fitted lateral curvature beside -k/2z, the
    speckle's lateral shift under the shear it predicts and what femu dic measured) or
    `identification` (per frame set and source of c(z), the composed lateral RMS error and each
    fat and quadriceps parameter's error range and coverage before and after the correction,
    then the provenance)."""
    d = ROOT / run_dir
    if what == "psf":
        psf = json.load(open(d / "psf_hann.json"))
        out = [f"| depth (mm) | lateral curvature fitted / -k/(2z) (rad/mm²) | shift under a shear of {psf['shear']} predicted by the PSF (px) | measured by femu dic (px) |",
               "|---|---|---|---|"]
        for r in psf["rows"]:
            if r["depth_mm"] in (3.0, 5.0, 10.0, 20.0, 30.0, 38.0):
                out.append(f"| {r['depth_mm']:g} | {r['alpha_fit']:.2f} / {r['alpha_lens']:.2f} | "
                           f"{r['shift_psf_px']:+.2f} | {r['measured_px']:+.2f} |")
        return "\n".join(out) + "\n"
    if what != "identification":
        raise SystemExit(f"shear_correction: no table {what!r} (psf, identification)")
    sets = [("hann", "apodized (Hann), pymust's PSF"), ("hann_lens", "apodized (Hann), closed form"),
            ("default", "default, pymust's PSF"), ("default_lens", "default, closed form")]
    params = ["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"]
    out = ["| frames, c(z) from | composed lateral RMS (px) | " + " | ".join(params) + " |",
           "|---|---|" + "---|" * len(params)]
    for i, (sub, label) in enumerate(sets):
        rows = list(csv.DictReader(open(d / sub / "parameters.csv")))
        lat = [r for r in csv.DictReader(open(d / sub / "lateral.csv")) if r["frame"] != "1"]
        n = len({r["seed"] for r in rows})

        def cell(p, before):
            r = [x for x in rows if x["parameter"] == p]
            e = [float(x["error_pct_uncorrected" if before else "error_pct"]) for x in r]
            c = sum(int(x["covered_uncorrected" if before else "covered"]) for x in r)
            return f"{round(min(e)):+d} to {round(max(e)):+d} % ({c}/{n})"
        if i % 2 == 0:
            rms = sum(float(r["rms_before_px"]) for r in lat) / len(lat)
            out.append(f"| {label.split(',')[0]}, {n} realizations, uncorrected | {rms:.2f} | "
                       + " | ".join(cell(p, True) for p in params) + " |")
        rms = sum(float(r["rms_after_px"]) for r in lat) / len(lat)
        out.append(f"| {label} | {rms:.2f} | " + " | ".join(cell(p, False) for p in params) + " |")
    return "\n".join(out) + "\n\n" + provenance(d).strip() + "\n"


def speckle_shift(run_dir):
    """bench/independent_us/speckle_shift_campaign.py's runs (hann/, default/ of RUN_DIR): per
    frame set and mode (the campaign's plain route without the shift, the scale fitted, the
    closed form fixed; the plain route, then the weighted one: the field's covariance plus the
    error estimated from a first fit), the range of the fitted scale (and, with scales.csv, of
    the scale the true fields support) and each fat and quadriceps parameter's error range and
    95 % coverage; then the provenance."""
    d = ROOT / run_dir
    sets = [("hann", "pymust, apodized (Hann)"), ("default", "pymust, default"),
            ("femu", "femu's own (Gaussian PSF, no shift)"),
            ("weighted_hann", "pymust, apodized (Hann), weighted route"),
            ("weighted_default", "pymust, default, weighted route")]
    params = ["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"]
    out = ["| frames | measurement model | scale κ | " + " | ".join(params) + " |",
           "|---|---|---|" + "---|" * len(params)]
    for sub, label in sets:
        rows = list(csv.DictReader(open(d / sub / "parameters.csv")))
        n = len({r["seed"] for r in rows})

        def cell(mode, p, before=False):
            r = [x for x in rows if x["mode"] == mode and x["parameter"] == p]
            e = [float(x["error_pct_uncorrected" if before else "error_pct"]) for x in r]
            c = sum(int(x["covered_uncorrected" if before else "covered"]) for x in r)
            return f"{round(min(e)):+d} to {round(max(e)):+d} % ({c}/{n})"
        modes = list(dict.fromkeys(r["mode"] for r in rows))
        out.append(f"| {label}, {n} realizations | without the shift | – | "
                   + " | ".join(cell(modes[0], p, True) for p in params) + " |")
        for mode in modes:
            k = [float(x["scale"]) for x in rows if x["mode"] == mode and x["parameter"] == params[0]]
            scale = f"{min(k):.2f} to {max(k):.2f}" if mode == "fitted" else f"{k[0]:g}"
            if mode == "fitted" and (d / sub / "scales.csv").exists():
                sc = list(csv.DictReader(open(d / sub / "scales.csv")))
                t = [float(x["true_field"]) for x in sc]
                scale += f" (true fields: {min(t):.2f} to {max(t):.2f}"
                if sc and "fitted_covers" in sc[0]:
                    scale += f"; held by {sum(int(x['fitted_covers']) for x in sc)}/{len(sc)} of its 95 % intervals"
                scale += ")"
            elif mode == "fitted" and rows and rows[0].get("scale_sd") and sub == "femu":
                # femu's own frames: no lateral phase, the true scale is 0.
                held = sum(abs(float(x["scale"])) <= 1.96 * float(x["scale_sd"])
                           for x in rows if x["mode"] == mode and x["parameter"] == params[0])
                scale += f" (0 held by {held}/{len(k)} of its 95 % intervals)"
            what = {"fitted": "shift, scale fitted", "fixed": "shift, closed form (scale 1)",
                    "none": "without the shift, this field",
                    "true": "shift, scale held at the true field's"}[mode]
            if mode == "true":
                scale = f"{min(k):.2f} to {max(k):.2f}"
            out.append(f"| | {what} | {scale} | " + " | ".join(cell(mode, p) for p in params) + " |")
    return "\n".join(out) + "\n\n" + provenance(d).strip() + "\n"


def profile_share(path, *phase):
    """The share of CPU samples of PHASE (the start of its name) in a committed profile's
    "CPU samples by phase" table (bench/perf/profile_*.txt, made by bench/perf/phases.py):
    `N %` (PHASE may be several words: the directive's arguments are split at spaces)."""
    phase = " ".join(phase)
    for line in open(ROOT / path):
        m = re.match(r"^\s*([\d.]+)%\s+\d+\s+(.*)$", line)
        if m and m.group(2).startswith(phase):
            return f"{float(m.group(1)):.0f} %"
    raise SystemExit(f"{ROOT / path}: no phase {phase!r} in its table of CPU samples by phase")


def idic_own_value(run_dir, seed, route, parameter):
    """One realization's relative error in the integrated-DIC campaign on femu's own sequences
    (campaign.csv): SEED, ROUTE (`idic`, `dic`, `weighted`) and PARAMETER: `+X %`, with
    `(interval holds the truth)` or `(interval misses the truth)`."""
    for r in csv.DictReader(open(ROOT / run_dir / "campaign.csv")):
        if r["seed"] == seed and r["parameter"] == parameter:
            # From the estimate and the reference: the file's DIC -> FEMU error columns are
            # unsigned (the seed's Eq. 4).
            e = 100 * (float(r[route]) / float(r["reference"]) - 1)
            held = "holds" if r[f"{route}_covered"].strip().lower() in ("true", "1") else "misses"
            return f"{'+' if e >= 0 else '−'}{abs(e):.2g} % (its interval {held} the truth)"
    raise SystemExit(f"{ROOT / run_dir / 'campaign.csv'}: no seed {seed} {parameter}")


def idic_error(run_dir, parameter, what="mean", route="integrated"):
    """One parameter of the integrated-DIC campaign on pymust's frames (idic_campaign.csv, ROUTE
    `integrated` unless given, or `dic-plain`, `dic-weighted`): WHAT `mean` (mean |error| %, two
    significant digits), `covered` or `above` (`N of M` realizations above the truth), or
    `provenance`."""
    if what == "provenance":
        return provenance(ROOT / run_dir).strip()
    rows = rows_where(ROOT / run_dir / "idic_campaign.csv", route=route, parameter=parameter)
    if what == "covered":
        return f"{sum(r['covered'] == '1' for r in rows)} of {len(rows)}"
    if what == "above":
        return f"{sum(float(r['relative_error']) > 0 for r in rows)} of {len(rows)}"
    mean = 100 * sum(abs(float(r['relative_error'])) for r in rows) / len(rows)
    return two_digits(mean)


def fields_above(run_dir, renderer, bound):
    """How many realizations of RENDERER in a campaign's fields.csv (bench/independent_us/
    campaign.py) have a lateral RMS error of the composed field above BOUND px:
    `N of M (largest X px)`."""
    rows = [r for r in csv.DictReader(open(ROOT / run_dir / "fields.csv"))
            if r["renderer"] == renderer and r["rms_ux_px"]]
    if not rows:
        raise SystemExit(f"{ROOT / run_dir / 'fields.csv'}: no fields of renderer {renderer!r}")
    ux = [float(r["rms_ux_px"]) for r in rows]
    return f"{sum(x > float(bound) for x in ux)} of {len(ux)} (largest {max(ux):.2f} px)"


def campaign_error(run_dir, renderer, route, parameter, what="mean"):
    """One parameter of one route on one renderer's frames (`pymust`, `femu`) of a campaign's
    campaign.csv: WHAT `mean` (mean |error|, %, two significant digits) or `covered` (`N of M`
    95 % intervals holding the truth) or `provenance`."""
    if what == "provenance":
        return provenance(ROOT / run_dir).strip()
    rows = rows_where(ROOT / run_dir / "campaign.csv", renderer=renderer, route=route, parameter=parameter)
    if what == "covered":
        return f"{sum(r['covered'] == '1' for r in rows)} of {len(rows)}"
    mean = sum(abs(float(r['error_pct'])) for r in rows) / len(rows)
    return two_digits(mean)


def lk_composition(run_dir, radius, smoothing, what="rms"):
    """scikit-image's Lucas-Kanade composition check on the real frames (bench/dic_lk/run.sh's
    lk_composition.csv): for RADIUS and SMOOTHING (px), WHAT `rms` (the composition's RMS
    difference, lateral and axial, `(X, Y)` px) or `provenance`."""
    d = ROOT / run_dir
    if what == "provenance":
        return provenance(d).strip()
    rows = rows_where(d / "lk_composition.csv", radius_px=radius, smoothing_px=smoothing)
    return f"({float(rows[0]['rms_x_px']):.2f}, {float(rows[0]['rms_y_px']):.2f})"


def on_bound(error):
    """Whether a relative error puts the estimate on a bound of the campaigns' studies (the
    reference / 4 and x 4: errors of -75 % and +300 %)."""
    return error <= -0.749 or error >= 2.99


def idic_own(run_dir):
    """The integrated-DIC campaign on femu's own sequences (bench/us_campaigns/
    final_defaults.sh, the idic_campaign example's campaign.csv): per parameter under the probe
    and route (integrated DIC, weighted FEMU, plain DIC → FEMU), mean / largest |error| and the
    95 % intervals that hold the truth, an estimate on a bound or not seen by the images counted
    as missed; then the times per realization (campaign_*.json)."""
    d = ROOT / run_dir
    rows = list(csv.DictReader(open(d / "campaign.csv")))
    routes = [("idic", "integrated DIC"), ("weighted", "weighted FEMU"), ("dic", "plain DIC → FEMU")]
    yes = lambda v: v.strip().lower() in ("true", "1")
    out = [provenance(d).strip(), ""]
    out.append("| parameter | " + " | ".join(f"{name}: mean / max \\|error\\|, intervals holding the truth"
                                               for _, name in routes) + " |")
    out.append("|---|" + "---|" * len(routes))
    totals = {k: [0, 0] for k, _ in routes}
    for par in UNDER_PROBE:
        rr = [r for r in rows if r["parameter"] == par]
        if not rr:
            raise SystemExit(f"{d / 'campaign.csv'}: no rows of {par}")
        cells = []
        for k, _ in routes:
            e = [100 * abs(float(r[f"{k}_error"])) for r in rr]
            # An estimate on a bound (the bounds are the reference / 4 .. x 4) or
            # not seen by the images is not a measurement: its interval is the bounds, which
            # hold the truth whatever the data; it counts as missed.
            held = sum(yes(r[f"{k}_covered"]) and not on_bound(float(r[f"{k}_error"]))
                       and yes(r.get(f"{k}_seen", "true")) for r in rr)
            totals[k][0] += held
            totals[k][1] += len(rr)
            cells.append(f"{sum(e) / len(e):.3g} / {max(e):.3g} %, {held} of {len(rr)}")
        out.append(f"| {par} | " + " | ".join(cells) + " |")
    out.append("| all four | " + " | ".join(f"{h} of {n} intervals" for h, n in totals.values()) + " |")
    seeds = sorted({int(r["seed"]) for r in rows})
    times = []
    for j in sorted(d.glob("campaign_*.json")):
        times += json.loads(j.read_text()).get("times", [])
    line = f"\nSeeds {seeds[0]}–{seeds[-1]}, {len(seeds)} realizations"
    if times and all("idic_total" in t and "dic_route" in t for t in times):
        it = [t["idic_total"] for t in times]
        dt = [t["dic_route"] for t in times]
        line += (f"; integrated DIC {min(it):.0f}–{max(it):.0f} s per realization (its discretization "
                 f"check included), the DIC → FEMU route {min(dt):.1f}–{max(dt):.1f} s")
    out.append(line + ".")
    return "\n".join(out) + "\n"


def idic_own_misses(run_dir):
    """The realizations of the campaign (campaign.csv) where the integrated DIC's estimate of a
    parameter under the probe is outside its 95 % interval, was not seen by the images, or is
    at a bound ([`on_bound`]): one line each, or a sentence
    saying there were none."""
    d = ROOT / run_dir
    rows = [r for r in csv.DictReader(open(d / "campaign.csv")) if r["parameter"] in UNDER_PROBE]
    yes = lambda v: v.strip().lower() in ("true", "1")
    lines = []
    for seed in dict.fromkeys(r["seed"] for r in rows):
        rr = [r for r in rows if r["seed"] == seed]
        bad = [r for r in rr if not yes(r["idic_covered"]) or not yes(r["idic_seen"])
               or on_bound(float(r["idic_error"]))]
        if not bad:
            continue
        what = []
        for r in rr:
            e = 100 * float(r["idic_error"])
            notes = []
            if on_bound(e / 100):
                notes.append("at a bound")
            if not yes(r["idic_seen"]):
                notes.append("not seen by the images")
            if not yes(r["idic_covered"]):
                notes.append("outside its interval")
            what.append(f"{r['parameter']} {'+' if e >= 0 else '−'}{abs(e):.3g} %"
                        + (f" ({', '.join(notes)})" if notes else ""))
        lines.append(f"- seed {seed} ({rr[0]['frequency_mhz']} MHz): " + ", ".join(what) + ".")
    if not lines:
        return "In every realization the integrated DIC's estimates of the four parameters are inside their bounds, seen by the images and inside their 95 % intervals.\n"
    return "\n".join(lines) + "\n"

def sensitivity_cost(run_dir):
    """The sensitivities' cost against the forward solve (bench/identify_perf/run.py's
    sensitivity.csv, femu-mech's sensitivity_cost example): per run and test, the best forward
    solve and the best sensitivities, the ratio of the bests and the median of the per-repeat
    ratios; then where the sensitivities' time goes and whether the 30 % goal is met."""
    d = ROOT / run_dir
    rows = list(csv.DictReader(open(d / "sensitivity.csv")))
    if not rows:
        raise SystemExit(f"{d / 'sensitivity.csv'}: no rows")
    out = [provenance(d).strip(), ""]
    out.append("| test | run | repeats | best forward solve (s) | best sensitivities (s) | ratio of the bests "
               "| median ratio |")
    out.append("|---|---|---|---|---|---|---|")
    ratios = {}
    for test in dict.fromkeys(r["test"] for r in rows):
        for run in dict.fromkeys(r["run"] for r in rows):
            rr = [r for r in rows if r["test"] == test and r["run"] == run]
            solve = min(float(r["solve_s"]) for r in rr)
            sens = min(float(r["sensitivities_s"]) for r in rr)
            per = sorted(float(r["sensitivities_s"]) / float(r["solve_s"]) for r in rr)
            ratios.setdefault(test, []).append(sens / solve)
            out.append(f"| {test} | {run} | {len(rr)} | {solve:.3f} | {sens:.3f} | {100 * sens / solve:.1f} % "
                       f"| {100 * per[len(per) // 2]:.1f} % |")
    parts = [("rhs_s", "rate forces and right-hand sides"), ("factorization_s", "refactorization"),
             ("triangular_s", "triangular solves"), ("residuals_s", "residuals")]
    span = lambda v: f"{min(v):.3f}" if f"{min(v):.3f}" == f"{max(v):.3f}" else f"{min(v):.3f}–{max(v):.3f}"
    out.append("\nWhere the sensitivities' time goes (every repeat of every run):\n")
    for test in dict.fromkeys(r["test"] for r in rows):
        rr = [r for r in rows if r["test"] == test]
        out.append(f"- {test}: " + ", ".join(f"{name} {span([float(r[k]) for r in rr])} s" for k, name in parts)
                   + ";")
    out[-1] = out[-1][:-1] + ".\n"
    c = ratios.get("contention", [])
    if c:
        met = sum(x <= 0.30 for x in c)
        out.append(f"The goal, sensitivities at most 30 % of the forward solve in contention, is "
                   + ("met" if met == len(c) else "not met" if met == 0 else "met in some runs only")
                   + f": {met} of {len(c)} runs on the ratio of the bests.")
    return "\n".join(out) + "\n"


def identify_summaries(run_dir):
    found = sorted((ROOT / run_dir).rglob("summary.json"))
    if not found:
        raise SystemExit(f"{ROOT / run_dir}: no summary.json")
    return [(f.parent.relative_to(ROOT / run_dir), json.loads(f.read_text())) for f in found]


def identify_virtual(run_dir):
    """`femu identify --elements N --repeat R --starts S` (bench/identify_perf/run.py's
    identify_3000/): per parameter, the mean and largest Eq. 4 error over the noise
    realizations, the sd the Jacobian predicts against the spread of the identified values, and
    the 95 % intervals holding the truth; the forward solves per start and the wall time."""
    d = ROOT / run_dir
    out = [provenance(d).strip()]
    for sub, s in identify_summaries(run_dir):
        fp = {f["name"]: f for f in s["free_parameters"]}
        out.append("")
        label = f"{s['test']}, {s['elements']} elements"
        out.append(f"{'Grouped' if s['grouped'] else 'Ungrouped'} ({label}, σ = {s['noise_sigma_mm']:.3g} mm, "
                   f"{s['points_in_tissue']} points in the tissue, {s['repeats']} noise realizations, "
                   f"{s['starts_per_repeat']} starts each):\n")
        out.append("| parameter | mean \\|Eq. 4 error\\| | largest | sd predicted (Jacobian) | sd of the identified values "
                   "| predicted / observed | 95 % intervals holding the truth |")
        out.append("|---|---|---|---|---|---|---|")
        for e in s["parameters"]:
            mean, mx = e.get("mean_relative_error"), e.get("max_relative_error")
            obs = e.get("sd_identified_relative")
            cov = e.get("coverage95")
            n = s["repeats"]
            ratio = f"{e['relative_sd'] / obs:.2f}" if obs else "–"
            out.append(
                f"| {e['name']} | {'–' if mean is None else f'{100 * mean:.2g} %'} "
                f"| {'–' if mx is None else f'{100 * mx:.2g} %'} | {100 * e['relative_sd']:.2g} % "
                f"| {'–' if obs is None else f'{100 * obs:.2g} %'} | {ratio} "
                f"| {'–' if cov is None else f'{round(cov * n)} of {n}'} |")
        fs = s["forward_solves_per_start"]
        out.append(f"\n{min(fs)}–{max(fs)} forward solves per start; {s['wall_time_s']:.0f} s in all.")
        means = [(e["name"], e.get("mean_relative_error")) for e in s["parameters"]]
        over = [n for n, m in means if m is not None and m >= (0.03 if n.startswith("C10") else 0.07)]
        ratios = [e["relative_sd"] / e["sd_identified_relative"] for e in s["parameters"]
                  if e.get("sd_identified_relative")]
        held = [round(e["coverage95"] * s["repeats"]) for e in s["parameters"] if e.get("coverage95") is not None]
        out.append("The seed's goal, a mean |error| below 3 % for C10 and below 7 % for D: "
                   + ("met by every parameter" if not over else "not met by " + ", ".join(over)) + "."
                   + (f" The sd the Jacobian predicts is {min(ratios):.2f}–{max(ratios):.2f} times the spread of "
                      f"the identified values over the realizations" if ratios else "")
                   + (f"; the 95 % intervals hold the truth in {sum(held)} of {len(held) * s['repeats']} cases "
                      f"({100 * sum(held) / (len(held) * s['repeats']):.0f} %)." if held else "."))
    return "\n".join(out) + "\n"


def _theta(s):
    return {e["name"]: e["identified"] for e in s["parameters"]}


def identify_levels(single_dir, multi_dir):
    """Single-level against multilevel identification at the paper scale (bench/identify_perf/
    run.py's paper_single/ and paper_multi/): forward solves, wall time, and how far apart the
    two optima are."""
    (_, a), = identify_summaries(single_dir)
    (_, b), = identify_summaries(multi_dir)
    ta, tb = _theta(a), _theta(b)
    dtheta = max(abs(tb[k] - ta[k]) / abs(ta[k]) for k in ta)
    dcost = abs(b["best_cost"] - a["best_cost"]) / abs(a["best_cost"])
    fa, fb = a["forward_solves_per_start"], b["forward_solves_per_start"]
    rf = b.get("refinement_forward_solves") or []
    out = [provenance(ROOT / single_dir).strip(), ""]
    out.append("| identification | elements of the starts | forward solves per start | refinement on the full mesh "
               "| wall time |")
    out.append("|---|---|---|---|---|")
    out.append(f"| single level | {a['elements']} | {min(fa)}–{max(fa)} ({len(fa)} starts) | – "
               f"| {a['wall_time_s']:.0f} s |")
    out.append(f"| multilevel | {b.get('coarse_elements')} | {min(fb)}–{max(fb)} ({len(fb)} starts) "
               f"| {', '.join(map(str, rf)) or '–'} forward solves on {b['elements']} | {b['wall_time_s']:.0f} s |")
    out.append(f"\nMultilevel {a['wall_time_s'] / b['wall_time_s']:.1f}x faster; the two optima: parameters within "
               f"{dtheta:.1g} relative, cost within {dcost:.1g} relative. "
               f"The multilevel run's provenance: {provenance(ROOT / multi_dir).strip()}")
    return "\n".join(out) + "\n"


def identify_fd(lm_dir, fd_dir):
    """One start of Levenberg-Marquardt (exact sensitivities) against BFGS on central finite
    differences (bench/identify_perf/run.py's fd_lm/ and fd_bfgs/), on the same data: each
    start's line of the run's log (cost, iterations, forward solves, time), and the error a run
    stopped with, if any."""
    pat = re.compile(r"repeat (\d+), start (\d+): cost ([-+.\deE]+), (\d+) iterations, (\d+) forward solves, "
                     r"([\d.]+) s")
    runs = []
    for d in (lm_dir, fd_dir):
        log = (ROOT / d / "log.txt").read_text()
        head = log.splitlines()[0]
        starts = [m.groups() for m in map(pat.search, log.splitlines()) if m]
        if len(starts) != 1:
            raise SystemExit(f"{ROOT / d / 'log.txt'}: {len(starts)} start lines, one expected")
        errors = [line for line in log.splitlines() if line.startswith("error:")]
        runs.append((head, starts[0], errors))
    out = [provenance(ROOT / lm_dir).strip(), ""]
    out.append("| optimizer | iterations | forward solves | time of the start | cost at the end |")
    out.append("|---|---|---|---|---|")
    for name, (_, (_, _, cost, its, solves, secs), _) in zip(
            ("Levenberg–Marquardt, exact sensitivities (`lm`)",
             "BFGS on central finite differences (`bfgs-fd`)"), runs):
        out.append(f"| {name} | {its} | {solves} | {float(secs):.1f} s | {cost} |")
    (head, a, _), (_, b, errors) = runs
    out.append(f"\n{head.split(': ', 1)[1]}: {float(b[5]) / float(a[5]):.0f}x in time, "
               f"{int(b[4]) / int(a[4]):.0f}x in forward solves"
               + ("; the same cost as printed." if a[2] == b[2] else "."))
    if errors:
        out.append(f"The BFGS run then stopped at the intervals (`{errors[-1]}`), before its summary: "
                   "its optimum's parameters were not written, only the cost above.")
    out.append(f"The BFGS run's provenance: {provenance(ROOT / fd_dir).strip()}")
    return "\n".join(out) + "\n"

def render(template):
    """A page from scripts/guide/templates/TEMPLATE: every `{{NAME ARG...}}` replaced by the
    table NAME makes of the result files ARG... (paths from the repository's root)."""
    funcs = {"shear_correction": shear_correction, "speckle_shift": speckle_shift, "dic_campaign": dic_campaign, "idic_campaign": idic_campaign, "performance": performance,
             "contact": contact, "recorded": recorded, "recorded_span": recorded_span,
             "recorded_provenance": recorded_provenance,
             "dic_real": dic_real, "dic_real_rms": dic_real_rms,
             "fields_above": fields_above, "campaign_error": campaign_error,
             "idic_own": idic_own, "idic_own_misses": idic_own_misses, "lk_composition": lk_composition,
             "dic_real_r": dic_real_r, "mudic_real": mudic_real, "substitution": substitution,
             "idic_error": idic_error, "substitution_table": substitution_table,
             "lateral_strain": lateral_strain, "bench": bench, "lateral_speckle": lateral_speckle,
             "profile_share": profile_share, "idic_own_value": idic_own_value,
             "sensitivity_cost": sensitivity_cost, "identify_virtual": identify_virtual,
             "identify_levels": identify_levels, "identify_fd": identify_fd}
    page = (TEMPLATES / template).read_text()
    return re.sub(r"\{\{(\w+)((?: [^ }]+)*)\}\}",
                  lambda m: funcs[m.group(1)](*m.group(2).split()).rstrip("\n"), page)


# The generated pages CI checks: page, and how it is made from result files in the repository.
GENERATED = {
    "docs/guide/src/measured/verification.md": lambda: verification(ROOT / "bench/verification/results"),
    "docs/guide/src/measured/performance.md": lambda: render("performance.md"),
    "docs/guide/src/measured/dic.md": lambda: render("dic.md"),
    "docs/guide/src/measured/idic.md": lambda: render("idic.md"),
    "docs/guide/src/measured/contact.md": lambda: render("contact.md"),
    "docs/guide/src/measured/runs.md": lambda: runs("bench/runs/results"),
}


def check():
    """Regenerates every page of GENERATED from the committed result files and fails when one
    differs from the committed page (nothing is measured again)."""
    bad = 0
    for page, make in GENERATED.items():
        want = make()
        have = (ROOT / page).read_text()
        if want != have:
            bad += 1
            sys.stderr.writelines(
                difflib.unified_diff(have.splitlines(True), want.splitlines(True), page, "generated")
            )
            print(f"{page} differs from what scripts/guide/tables.py makes of its result files",
                  file=sys.stderr)
    if bad:
        print("regenerate: docs/guide/src/developer/guide.md says how", file=sys.stderr)
        sys.exit(1)
    print(f"generated pages up to date: {len(GENERATED)}", file=sys.stderr)
    return ""


def main(argv):
    if len(argv) < 2 or (len(argv) < 3 and argv[1] != "check"):
        print(__doc__, file=sys.stderr)
        return 2
    kind, args = argv[1], argv[2:]
    fn = {"demo": demo, "convergence": convergence, "bench": bench, "page": page,
          "verification": verification, "check": check, "render": render, "runs": runs}.get(kind)
    if fn is None:
        print(f"unknown table {kind!r}", file=sys.stderr)
        return 2
    sys.stdout.write(fn(*args))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
