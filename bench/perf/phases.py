#!/usr/bin/env python3
"""Where a `femu solve` spends its CPU time, from a `perf record --call-graph dwarf` profile.

    perf record --call-graph dwarf,16384 -F 2000 -o solve.data -- femu solve DECK --out DIR --quiet --no-figures
    python3 bench/perf/phases.py solve.data

Each sample goes to the phase of the innermost frame of its stack that names one (the list
below, checked from the leaf up); a sample of faer's update kernel whose stack could not be
unwound (a `gemm` leaf) goes to the factorization. Prints the share of each phase and, for the
phases given with --leaves, their hottest leaf functions.
"""

import argparse
import collections
import subprocess

PHASES = [
    ("read deck", ["femu_mesh::inp::read_inp", "Model::from_deck"]),
    ("setup: AMD ordering", ["amd::order", "amd_node_order"]),
    ("setup: split along the elimination tree", ["split_by_elimination_tree"]),
    ("setup: symbolic LDLT of the halves", ["split::Half::new"]),
    ("setup: split checks, separator", ["SplitLdlt::new"]),
    ("setup: transposed positions", ["transpose_positions"]),
    ("setup: pattern and element slots", ["Layout::new", "element_slots", "TangentGather::new", "ResidualGather::new"]),
    ("setup: other", ["Assembly::new", "ContactState::new", "NewtonWork::new", "StaticSolver::new"]),
    ("assembly: element matrices", ["element_forces", "evaluate_element"]),
    ("assembly: gathers", ["TangentGather::gather", "ResidualGather::gather"]),
    ("assembly: other", ["Assembly::assemble", "add_pressure", "Assembly::element_forces"]),
    ("factorization: halves (supernodal LDLT)", ["Half::factorize", "private_gemm_x86"]),
    ("factorization: symmetry check", ["SparseSolver::asymmetry"]),
    ("factorization: separator (dense)", ["SplitLdlt::factorize", "SparseSolver::factorize"]),
    ("triangular solves", ["solve_many_in_place", "solve_many"]),
    ("output (CSV, VTU)", ["femu_mech::output", "write_solved", "write_result", "femu_mesh::vtu"]),
    ("Newton driver", ["StaticSolver::solve", "solver::newton::"]),
    ("main, other", ["femu::main", "solve_file"]),
]


def samples(path):
    out = subprocess.run(["perf", "script", "-i", path, "-F", "ip,sym"], capture_output=True, text=True).stdout
    stack = []
    for line in out.splitlines():
        if line.strip():
            stack.append(line.strip().split(None, 1)[-1])
        elif stack:
            yield stack
            stack = []
    if stack:
        yield stack


def phase_of(stack):
    for frame in stack:
        for name, keys in PHASES:
            if any(k in frame for k in keys):
                return name
    if "gemm" in stack[0]:
        return "factorization: halves (supernodal LDLT)"
    return "other: " + stack[0][:60]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("--leaves", default="", help="comma-separated phases whose leaves to list")
    a = ap.parse_args()
    counts = collections.Counter()
    leaves = collections.defaultdict(collections.Counter)
    for stack in samples(a.data):
        p = phase_of(stack)
        counts[p] += 1
        leaves[p][stack[0][:80]] += 1
    total = sum(counts.values())
    print(f"{'share':>6}  {'samples':>7}  phase")
    for name, v in counts.most_common():
        if v / total < 0.003:
            continue
        print(f"{100 * v / total:5.1f}%  {v:7d}  {name}")
    print(f"total {total} samples")
    for name in filter(None, a.leaves.split(",")):
        for p in [p for p in leaves if p.startswith(name)]:
            print(f"\n{p}: hottest leaves")
            for leaf, v in leaves[p].most_common(10):
                print(f"{100 * v / total:5.1f}%  {leaf}")


if __name__ == "__main__":
    main()
