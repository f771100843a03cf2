#!/usr/bin/env python3
"""Run the guide's examples, so that the commands it shows keep working.

    python3 scripts/guide/run_examples.py docs/guide/src [--femu target/debug/femu]
        [--python PYTHON] [--page how-to/deck.md] [--list]

A fenced block is an example when an HTML comment right before it (blank lines allowed) says
what to do with it:

    <!-- example: run -->            run it: sh/bash blocks with bash (-e -u -o pipefail),
                                     python blocks with --python (a Python that imports femu)
    <!-- example: file NAME -->      write its text to NAME (a study, a table) for later blocks
    <!-- example: skip REASON -->    do not run it; REASON is printed (a cluster, a recording)

Every sh, bash and python block of the tutorial and how-to pages must carry one of these
(an unmarked one is an error), so that no command of theirs is left unchecked silently. The
blocks of one page run in order in one fresh folder `work/`, beside which `shared` links to the
repository's `../shared` (so `../shared/data/...` resolves as from a clone's root) and `docs`,
`crates` link to the repository's; `femu` is first on the PATH. A block that uses
`../shared/data` where it is absent, or Python where none imports femu, is skipped with a line
saying so. Exits 1 when a block fails or is unmarked.
"""

import argparse
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time

MARK = re.compile(r"<!--\s*example:\s*(run|file|skip)\s*(.*?)\s*-->")
FENCE = re.compile(r"^(```+|~~~+)\s*([\w+-]*)")
SHELL = {"sh", "bash", "shell", "console"}
PYTHON = {"python", "py"}
MUST_MARK = ("tutorial/", "how-to/")
BLOCK_TIMEOUT_S = 600


def blocks(text):
    """(line, language, body, mark) of every fenced block; mark is (kind, arg) or None."""
    lines = text.split("\n")
    out, i, pending = [], 0, None
    while i < len(lines):
        line = lines[i]
        m = MARK.search(line)
        if m:
            pending = (m.group(1), m.group(2))
            i += 1
            continue
        f = FENCE.match(line.strip())
        if f:
            fence, lang = f.group(1), f.group(2).lower()
            start = i
            body = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith(fence):
                body.append(lines[i])
                i += 1
            out.append((start + 1, lang.split(",")[0], "\n".join(body) + "\n", pending))
            pending = None
        elif line.strip():
            pending = None
        i += 1
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("src", type=pathlib.Path)
    ap.add_argument("--femu", type=pathlib.Path, default=pathlib.Path("target/debug/femu"))
    ap.add_argument("--python", default=None, help="a Python that imports femu")
    ap.add_argument("--page", action="append", default=[], help="only these pages")
    ap.add_argument("--list", action="store_true", help="list the examples, run nothing")
    args = ap.parse_args()

    repo = pathlib.Path(__file__).resolve().parents[2]
    shared = repo.parent / "shared"
    femu = args.femu.resolve()
    if not args.list and not femu.exists():
        print(f"no femu binary at {femu}", file=sys.stderr)
        return 1
    # The examples run in a scratch folder: a Python given by a relative path is made absolute
    # (without resolving symbolic links, which would leave a virtual environment).
    if args.python and os.sep in args.python:
        args.python = os.path.abspath(args.python)
    python_ok = bool(args.python) and (
        subprocess.run([args.python, "-c", "import femu"], capture_output=True).returncode == 0
    )

    failures, ran, skipped = [], 0, 0
    t0 = time.monotonic()
    for page in sorted(args.src.rglob("*.md")):
        rel = page.relative_to(args.src).as_posix()
        if args.page and rel not in args.page:
            continue
        found = blocks(page.read_text(encoding="utf-8"))
        must = rel.startswith(MUST_MARK)
        todo = []
        for line, lang, body, mark in found:
            runnable = lang in SHELL or lang in PYTHON
            if mark is None:
                if must and runnable:
                    failures.append(f"{rel}:{line}: a {lang} block without an example mark")
                continue
            todo.append((line, lang, body, mark))
        if not todo:
            continue
        if args.list:
            for line, lang, _, (kind, arg) in todo:
                print(f"{rel}:{line}: {kind} {arg} ({lang})")
            continue
        root = pathlib.Path(tempfile.mkdtemp(prefix="femu-guide-"))
        work = root / "work"
        work.mkdir()
        if shared.exists():
            (root / "shared").symlink_to(shared)
        for name in ("docs", "crates", "scripts"):
            (work / name).symlink_to(repo / name)
        env = dict(os.environ)
        env["PATH"] = f"{femu.parent}{os.pathsep}{env.get('PATH', '')}"
        if femu.name != "femu":
            (root / "bin").mkdir()
            (root / "bin" / "femu").symlink_to(femu)
            env["PATH"] = f"{root / 'bin'}{os.pathsep}{env['PATH']}"
        for line, lang, body, (kind, arg) in todo:
            where = f"{rel}:{line}"
            if kind == "skip":
                print(f"SKIPPED {where}: {arg}")
                skipped += 1
                continue
            if kind == "file":
                target = work / arg
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(body, encoding="utf-8")
                print(f"file    {where}: {arg}")
                continue
            if "../shared/data" in body and not (shared / "data").exists():
                print(f"SKIPPED {where}: needs ../shared/data, absent here")
                skipped += 1
                continue
            if lang in PYTHON:
                if not python_ok:
                    print(f"SKIPPED {where}: needs a Python with the femu package (--python)")
                    skipped += 1
                    continue
                cmd = [args.python, "-c", body]
            elif lang in SHELL:
                cmd = ["bash", "-euo", "pipefail", "-c", body]
            else:
                failures.append(f"{where}: cannot run a {lang!r} block")
                continue
            start = time.monotonic()
            try:
                res = subprocess.run(
                    cmd, cwd=work, env=env, capture_output=True, text=True,
                    timeout=BLOCK_TIMEOUT_S,
                )
                code, out = res.returncode, res.stdout + res.stderr
            except subprocess.TimeoutExpired as e:
                code, out = "timeout", f"{e.stdout or ''}{e.stderr or ''}"
            took = time.monotonic() - start
            ran += 1
            if code == 0:
                print(f"ok      {where} ({took:.1f} s)")
            else:
                print(f"FAILED  {where} (exit {code}, {took:.1f} s)\n{body}---\n{out[-4000:]}")
                failures.append(f"{where}: exit {code}")
                break  # later blocks of the page depend on this one
        shutil.rmtree(root, ignore_errors=True)

    for f in failures:
        print(f"error: {f}")
    if not args.list:
        print(
            f"guide examples: {ran} run, {skipped} skipped, {len(failures)} failed, "
            f"{time.monotonic() - t0:.0f} s"
        )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
