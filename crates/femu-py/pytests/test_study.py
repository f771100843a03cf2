"""The seed's numerical example (``femu demo``) from Python against the ``femu`` command: the
same numbers to the last printed digit (in fact bit for bit: the same library functions run),
typed results that mirror every field of the Rust summaries, progress as tqdm-style events."""

import csv
import json
import time

import pytest

import femu
from _helpers import differences, plain, run_cli, rust_e


class Recorder:
    """A progress reporter that keeps every event."""

    def __init__(self):
        self.events = []

    def note(self, line):
        self.events.append(("note", line))

    def warn(self, line):
        self.events.append(("warn", line))

    def start(self, task, what, total):
        self.events.append(("start", task, what, total))

    def inc(self, task, n):
        self.events.append(("inc", task, n))

    def message(self, task, text):
        self.events.append(("message", task, text))

    def end(self, task):
        self.events.append(("end", task))


@pytest.fixture(scope="module")
def demos(tmp_path_factory, femu_cli):
    """``femu demo`` run by the command and from Python, side by side; their wall times."""
    root = tmp_path_factory.mktemp("demo")
    t = time.perf_counter()
    run_cli(femu_cli, "demo", "--out", root / "cli", "--quiet")
    cli_s = time.perf_counter() - t
    recorder = Recorder()
    t = time.perf_counter()
    result = femu.demo(root / "py", progress=recorder)
    py_s = time.perf_counter() - t
    print(f"femu demo: command {cli_s:.1f} s, Python {py_s:.1f} s (ratio {py_s / cli_s:.3f})")
    return root / "cli", result, recorder


def test_identified_parameters_agree_with_the_command_to_the_last_printed_digit(demos):
    cli, result, _ = demos
    assert set(result.identification) == {"grouped", "ungrouped"}
    for grouping, summary in result.identification.items():
        with open(cli / "identify" / grouping / "parameters.csv") as f:
            rows = list(csv.DictReader(f))
        assert [r["name"] for r in rows] == [p.name for p in summary.parameters]
        for row, p in zip(rows, summary.parameters):
            # The formats of parameters.csv (femu_study::steps::identify).
            assert row["identified"] == rust_e(p.identified, 9), (grouping, p.name)
            assert row["reference"] == rust_e(p.reference, 6)
            assert row["relative_error"] == rust_e(p.relative_error, 6)
            assert row["relative_sd"] == rust_e(p.relative_sd, 6)
            assert row["ci95_low"] == rust_e(p.ci95[0], 9)
            assert row["ci95_high"] == rust_e(p.ci95[1], 9)


def test_every_number_of_every_step_equals_the_commands(demos):
    """Every number of every summary, compared exactly (timings and paths aside)."""
    cli, result, _ = demos
    load = lambda *p: json.loads(cli.joinpath(*p).read_text())  # noqa: E731
    diffs = differences(plain(result.sensitivity), load("sensitivity", "summary.json"))
    for test, s in result.forward.items():
        diffs += differences(plain(s), load("forward", test, "summary.json"), f"forward/{test}")
    for g, s in result.identification.items():
        diffs += differences(plain(s), load("identify", g, "summary.json"), f"identify/{g}")
    diffs += differences(plain(result.record), load("steps.json"))
    assert diffs == []
    # And the files themselves.
    for name in ("parameters.csv", "starts.csv"):
        for g in ("grouped", "ungrouped"):
            py_text = (result.folder / "identify" / g / name).read_text()
            assert py_text == (cli / "identify" / g / name).read_text(), (g, name)
    assert (result.folder / "measurement" / "measured.csv").read_text() == (
        cli / "measurement" / "measured.csv"
    ).read_text()


def test_results_mirror_every_field_of_the_rust_summaries(demos):
    _, result, _ = demos
    objects = [result.record, result.sensitivity]
    objects += list(result.forward.values()) + list(result.identification.values())
    for obj in objects:
        assert femu.results.unmirrored(obj) == [], type(obj).__name__


def test_tables_for_pandas(demos):
    pd = pytest.importorskip("pandas")
    _, result, _ = demos
    g = result.identification["grouped"]
    table = g.table()
    assert isinstance(table, pd.DataFrame)
    assert list(table.index) == [p.name for p in g.parameters]
    assert (table["ci95_low"] < table["identified"]).all()
    assert (table["identified"] < table["ci95_high"]).all()
    corr = g.correlation_table()
    assert corr.shape == (len(g.parameters), len(g.parameters))
    assert all(abs(corr.iloc[k, k] - 1.0) < 1e-12 for k in range(len(corr)))
    history = g.cost_history()
    accepted = history[history["accepted"]]
    assert accepted["cost"].is_monotonic_decreasing
    # The optimum's cost is the last accepted step's.
    assert accepted["cost"].iloc[-1] == g.best.cost
    ranking = result.sensitivity.identifiability_table()
    assert {"grouped", "ungrouped"} == set(ranking["grouping"])
    index = result.sensitivity.index_table()
    assert index.shape == (10, 3)
    newton = result.forward["compression-anterior"].newton_table()
    assert newton["residual_norm"].iloc[-1] < 1e-6


def test_progress_arrives_as_notes_and_bars(demos):
    _, _, recorder = demos
    kinds = [e[0] for e in recorder.events]
    assert "note" in kinds
    starts = {e[1]: e for e in recorder.events if e[0] == "start"}
    ends = {e[1] for e in recorder.events if e[0] == "end"}
    assert starts and set(starts) == ends  # every bar closed
    for task, (_, _, what, total) in starts.items():
        if total is not None:
            done = sum(e[2] for e in recorder.events if e[0] == "inc" and e[1] == task)
            assert done == total, what
    assert any("identification" in e[2] for e in starts.values())
