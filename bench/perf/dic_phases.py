#!/usr/bin/env python3
"""Where `femu dic` spends its CPU time, from `perf record --call-graph dwarf` profiles: each
sample goes to the first phase of PHASES that a frame of its stack names (the covariance before
the correlation: its sparse solves are femu_dic::sparse frames too). Samples whose stack could
not be unwound (faer's gemm kernels, rayon workers without their caller) go to "other".

    perf record -F 199 --call-graph dwarf,16384 -o dic.data -- femu dic REF DEF --out DIR -q
    python3 bench/perf/dic_phases.py dic.data [more.data ...]
"""

import collections
import subprocess
import sys

PHASES = [
    ("nodal covariance", ["quality::sandwich", "quality::covariance", "femu_dic::selected::"]),
    ("grid covariance (field_covariance.mtx)", ["output::grid_covariance", "combined_covariance"]),
    ("maps (PNG)", ["femu_dic::figures::", "femu_plot::"]),
    ("tables and matrices (CSV, MTX, VTU)", ["command::write_tables", "output::write_", "output::grid_with_quality"]),
    ("correlation (every rung of the ladder)", ["femu_dic::solver::", "femu_dic::bspline::", "femu_dic::fft::", "femu_dic::anderson::", "femu_dic::auto::", "femu_dic::sparse::", "rustfft::"]),
    ("reading the images", ["GreyImage::open", "femu_dic::read::"]),
]


def phase_of(stack):
    for name, keys in PHASES:  # in the order of PHASES, anywhere in the stack
        if any(k in frame for frame in stack for k in keys):
            return name
    return "other (start-up, rayon idle/unwound)"


def main():
    for path in sys.argv[1:]:
        out = subprocess.run(["perf", "script", "-i", path, "-F", "ip,sym"], capture_output=True, text=True).stdout
        counts = collections.Counter()
        stack = []
        for line in out.splitlines() + [""]:
            line = line.strip()
            if line:
                stack.append(line)
            elif stack:
                counts[phase_of(stack)] += 1
                stack = []
        total = sum(counts.values())
        print(f"{path}: {total} samples")
        for name, _ in PHASES + [("other (start-up, rayon idle/unwound)", None)]:
            print(f"  {100 * counts[name] / total:5.1f} %  {name}")


if __name__ == "__main__":
    main()
