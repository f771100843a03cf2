"""Checks of scripts/compare_runs.py on small run folders made here."""

import json
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
import compare_runs  # noqa: E402


def write(root, name, text):
    path = os.path.join(root, name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def make_run(root, c10=1.75, wall=3.2, csv_value="0.125", extra=False, started=1795822256):
    summary = {
        "started_unix_s": started,
        "timings": {"solve_s": wall, "total_s": wall + 1},
        "parameters": [{"name": "C10_FAT", "value": c10, "unit": "kPa"}],
        "converged": True,
    }
    write(root, "identify/summary.json", json.dumps(summary))
    write(root, "measurement/measured.csv", f"x,y,ux\n1.0,2.0,{csv_value}\n")
    write(root, "report.html",
          "<p><b>demo</b> — done in %.1f s.</p><table><tr><th>step</th><th>time (s)</th></tr>"
          "<tr><td>model</td><td>%.2f</td></tr></table><p>C10 %.4g kPa</p>" % (wall, wall, c10))
    if extra:
        write(root, "extra.txt", "x")


def test_same_results_other_timings_agree(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    make_run(a)
    make_run(b, wall=9.7, started=1795822999)
    diffs = compare_runs.compare_folders(str(a), str(b), 1e-12, 0.0)
    assert diffs.per_file == {}, diffs.lines


def test_a_changed_parameter_is_found_in_json_csv_and_report(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    make_run(a)
    # A relative change of 1e-9 in C10, beyond the 1e-12 tolerance.
    make_run(b, c10=1.75 * (1 + 1e-9), csv_value="0.12500001")
    diffs = compare_runs.compare_folders(str(a), str(b), 1e-12, 0.0)
    assert set(diffs.per_file) == {"identify/summary.json", "measurement/measured.csv"}
    # Within a looser tolerance they agree (the report prints C10 to 4 digits: same text).
    loose = compare_runs.compare_folders(str(a), str(b), 1e-6, 0.0)
    assert loose.per_file == {}, loose.lines


def test_missing_and_extra_files_are_reported(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    make_run(a)
    make_run(b, extra=True)
    diffs = compare_runs.compare_folders(str(a), str(b), 1e-12, 0.0)
    assert diffs.per_file == {"extra.txt": 1}
    assert compare_runs.main([str(a), str(b)]) == 1
    assert compare_runs.main([str(a), str(a)]) == 0
    assert compare_runs.main([str(a), str(tmp_path / "nowhere")]) == 2
