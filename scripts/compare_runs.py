#!/usr/bin/env python3
"""Compare two femu run folders file by file: same files, same values.

A change to femu's internals (a restructure, a faster solver path) must leave every output of a
run the same. This script checks that between a run folder made before the change and one made
after it, on the same study:

- both folders hold the same set of files;
- JSON files: same keys and structure; strings equal; numbers equal within the tolerance;
  measurements of the run itself (timings, start time, peak memory) are skipped, since two runs
  never agree on them;
- CSV, Matrix Market, Abaqus decks, VTU (ASCII) and other text: the text between the numbers is
  identical, and the numbers agree within the tolerance;
- HTML reports: as text, with wall-clock figures masked (the columns of tables headed "time (s)",
  "solve (s)" or "sensitivities / solve", "… s." durations in prose, Unix timestamps);
- PNG and other binary files: byte-identical, or (PNG, with Pillow installed) the same pixels.

Numbers a and b agree when |a - b| <= atol + rtol * max(|a|, |b|) (defaults rtol = 1e-12,
atol = 0).

Usage:
    python3 scripts/compare_runs.py BEFORE AFTER [--rtol 1e-12] [--atol 0] [--max-report 20]

Exit status 0 when the folders agree, 1 when they differ (every difference is listed), 2 on a
usage error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from html.parser import HTMLParser

# JSON keys that hold measurements of the run itself (wall-clock times, their ratios, the start
# time, peak memory): they differ between any two runs of the same binary and are not compared.
TIMING_KEY = re.compile(
    r"^(seconds|total_seconds|started_unix_s|finished_unix_s|wall_time_s|.*_time_s|solve_s"
    r"|sensitivity_over_solve|peak_memory_mb|peak_rss_mb|.*_memory_mb"
    r"|idic_s|dic_femu_s|dic_weighted_s|identification_s|image_s|discretization_s|time_s"
    r"|correlation_s)$"
)
# Every numeric field of a "timings" object is a wall-clock measurement.
TIMING_OBJECTS = {"timings", "timing", "timings_s"}

TEXT_EXTENSIONS = {
    ".json", ".csv", ".mtx", ".inp", ".vtu", ".vtk", ".txt", ".md", ".toml", ".svg", ".dat",
    ".msh", ".tsv", ".html", ".log",
}

NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan|NaN|Inf)")

# Headers of report table columns that hold wall-clock times.
TIMING_HEADER = re.compile(r"time \(s\)|^time_s$|solve \(s\)|sensitivities / solve|\(ms\)|seconds", re.I)


class Differences:
    """Collects differences, one line each, and counts them per file."""

    def __init__(self, max_report: int):
        self.lines: list[str] = []
        self.per_file: dict[str, int] = {}
        self.max_report = max_report

    def add(self, path: str, message: str) -> None:
        count = self.per_file.get(path, 0) + 1
        self.per_file[path] = count
        if count <= self.max_report:
            self.lines.append(f"{path}: {message}")
        elif count == self.max_report + 1:
            self.lines.append(f"{path}: … further differences not listed")


def numbers_agree(a: float, b: float, rtol: float, atol: float) -> bool:
    if math.isnan(a) and math.isnan(b):
        return True
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= atol + rtol * max(abs(a), abs(b))


def compare_json(a, b, where: str, path: str, diffs: Differences, rtol: float, atol: float,
                 parent_key: str = "") -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            here = f"{where}.{key}" if where else key
            if key not in a:
                diffs.add(path, f"{here} only in the second run")
                continue
            if key not in b:
                diffs.add(path, f"{here} only in the first run")
                continue
            if TIMING_KEY.match(key) or parent_key in TIMING_OBJECTS and _is_number(a[key]):
                continue
            compare_json(a[key], b[key], here, path, diffs, rtol, atol, key)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.add(path, f"{where}: {len(a)} items against {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b)):
            compare_json(x, y, f"{where}[{i}]", path, diffs, rtol, atol, parent_key)
    elif _is_number(a) and _is_number(b):
        if not numbers_agree(float(a), float(b), rtol, atol):
            diffs.add(path, f"{where}: {a!r} against {b!r}")
    elif a != b:
        diffs.add(path, f"{where}: {a!r} against {b!r}")


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def compare_text(a: str, b: str, path: str, diffs: Differences, rtol: float, atol: float) -> None:
    lines_a = a.splitlines()
    lines_b = b.splitlines()
    if len(lines_a) != len(lines_b):
        diffs.add(path, f"{len(lines_a)} lines against {len(lines_b)}")
        return
    for number, (la, lb) in enumerate(zip(lines_a, lines_b), start=1):
        if la == lb:
            continue
        tokens_a = NUMBER.split(la)
        tokens_b = NUMBER.split(lb)
        values_a = NUMBER.findall(la)
        values_b = NUMBER.findall(lb)
        if tokens_a != tokens_b or len(values_a) != len(values_b):
            diffs.add(path, f"line {number}: {la.strip()[:120]!r} against {lb.strip()[:120]!r}")
            continue
        for va, vb in zip(values_a, values_b):
            if not numbers_agree(float(va), float(vb), rtol, atol):
                diffs.add(path, f"line {number}: {va} against {vb}")


class _HtmlMasker(HTMLParser):
    """Rebuilds an HTML page as text, one cell or text run per line, with wall-clock figures
    replaced by a placeholder."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.out: list[str] = []
        self.headers: list[str] = []
        self.in_header = False
        self.column = -1
        self.in_cell = False
        self.cell_text: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.headers = []
        elif tag == "tr":
            self.column = -1
        elif tag in ("th", "td"):
            self.column += 1
            self.in_cell = True
            self.in_header = tag == "th"
            self.cell_text = []
        self.out.append(f"<{tag} {sorted(attrs)}>")

    def handle_endtag(self, tag):
        if tag in ("th", "td") and self.in_cell:
            text = " ".join(self.cell_text).strip()
            if self.in_header:
                self.headers.append(text)
            elif 0 <= self.column < len(self.headers) and TIMING_HEADER.search(
                self.headers[self.column]
            ):
                text = "<time>"
            self.out.append(_mask_prose(text))
            self.in_cell = False
        self.out.append(f"</{tag}>")

    def handle_data(self, data):
        if self.in_cell:
            self.cell_text.append(data)
        elif data.strip():
            self.out.append(_mask_prose(data.strip()))


def _mask_prose(text: str) -> str:
    # Durations in prose ("done in 20.1 s", "9.1 s.", "310 ms") and Unix timestamps.
    text = re.sub(r"\b\d+(?:\.\d+)?\s?(?:s|ms|min)\b(?=[\s.,;)]|$)", "<time>", text)
    # The ratio of two routes' times ("... against 9.0 s for the DIC → FEMU route ...: ratio 1.64").
    text = re.sub(r"\bratio \d+(?:\.\d+)?", "ratio <time ratio>", text)
    return re.sub(r"\b1[5-9]\d{8}\b", "<unix time>", text)


def compare_html(a: str, b: str, path: str, diffs: Differences, rtol: float, atol: float) -> None:
    masked = []
    for page in (a, b):
        parser = _HtmlMasker()
        parser.feed(page)
        parser.close()
        masked.append("\n".join(parser.out))
    compare_text(masked[0], masked[1], path, diffs, rtol, atol)


def compare_png(a_path: str, b_path: str, path: str, diffs: Differences) -> None:
    try:
        from PIL import Image, ImageChops
    except ImportError:
        diffs.add(path, "the PNG files differ in bytes (install Pillow to compare their pixels)")
        return
    with Image.open(a_path) as ia, Image.open(b_path) as ib:
        if ia.size != ib.size:
            diffs.add(path, f"image size {ia.size} against {ib.size}")
            return
        ra, rb = ia.convert("RGBA"), ib.convert("RGBA")
        box = ImageChops.difference(ra, rb).getbbox()
        if box is not None:
            diffs.add(path, f"pixels differ inside the box {box}")


def list_files(root: str) -> set[str]:
    found = set()
    for folder, _, names in os.walk(root):
        for name in names:
            found.add(os.path.relpath(os.path.join(folder, name), root))
    return found


def compare_folders(before: str, after: str, rtol: float, atol: float,
                    max_report: int = 20) -> Differences:
    diffs = Differences(max_report)
    files_a, files_b = list_files(before), list_files(after)
    for name in sorted(files_a - files_b):
        diffs.add(name, "only in the first run")
    for name in sorted(files_b - files_a):
        diffs.add(name, "only in the second run")
    for name in sorted(files_a & files_b):
        pa, pb = os.path.join(before, name), os.path.join(after, name)
        with open(pa, "rb") as fa, open(pb, "rb") as fb:
            ba, bb = fa.read(), fb.read()
        if ba == bb:
            continue
        ext = os.path.splitext(name)[1].lower()
        if ext == ".png":
            compare_png(pa, pb, name, diffs)
            continue
        if ext not in TEXT_EXTENSIONS:
            diffs.add(name, "binary files differ")
            continue
        try:
            ta, tb = ba.decode("utf-8"), bb.decode("utf-8")
        except UnicodeDecodeError:
            diffs.add(name, "files differ and are not UTF-8 text")
            continue
        if ext == ".json":
            try:
                ja, jb = json.loads(ta), json.loads(tb)
            except json.JSONDecodeError as err:
                diffs.add(name, f"not valid JSON: {err}")
                continue
            compare_json(ja, jb, "", name, diffs, rtol, atol)
        elif ext == ".html":
            compare_html(ta, tb, name, diffs, rtol, atol)
        else:
            compare_text(ta, tb, name, diffs, rtol, atol)
    return diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", help="run folder made before the change")
    parser.add_argument("after", help="run folder made after the change")
    parser.add_argument("--rtol", type=float, default=1e-12, help="relative tolerance (1e-12)")
    parser.add_argument("--atol", type=float, default=0.0, help="absolute tolerance (0)")
    parser.add_argument("--max-report", type=int, default=20,
                        help="differences listed per file (20)")
    args = parser.parse_args(argv)
    for folder in (args.before, args.after):
        if not os.path.isdir(folder):
            print(f"error: {folder} is not a folder", file=sys.stderr)
            return 2
    diffs = compare_folders(args.before, args.after, args.rtol, args.atol, args.max_report)
    n_files = len(list_files(args.before) | list_files(args.after))
    if diffs.per_file:
        print("\n".join(diffs.lines))
        print(f"{len(diffs.per_file)} of {n_files} files differ "
              f"(rtol {args.rtol:g}, atol {args.atol:g})")
        return 1
    print(f"all {n_files} files agree (rtol {args.rtol:g}, atol {args.atol:g}; "
          "timings and memory skipped)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
