"""Shared fixtures of the femu package's tests: the ``femu`` command to compare with, the
shared data folder, and Rust's float formatting (to compare with what the command prints).

Environment:
- ``FEMU_BIN``: the ``femu`` binary built from the same sources (``.ci/run`` sets it); without
  it ``target/release/femu`` or ``target/debug/femu``, whichever is newer; tests that compare
  with the command skip with a message when there is none, or fail with ``FEMU_REQUIRE_CLI=1``.
- ``FEMU_SHARED_DATA``: the shared data folder (default ``../shared/data`` of the repository);
  tests that read it skip with a message when it is absent.
"""

import os
from pathlib import Path

import pytest

from _helpers import REPO


def _cli() -> Path:
    given = os.environ.get("FEMU_BIN")
    if given:
        p = Path(given)
        if not p.is_file():
            pytest.fail(f"FEMU_BIN={given}: no such file")
        return p
    found = [REPO / "target" / d / "femu" for d in ("release", "debug")]
    found = [p for p in found if p.is_file()]
    if not found:
        msg = "no femu binary (set FEMU_BIN or build it: cargo build --release --bin femu)"
        if os.environ.get("FEMU_REQUIRE_CLI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return max(found, key=lambda p: p.stat().st_mtime)


@pytest.fixture(scope="session")
def femu_cli() -> Path:
    """The ``femu`` command."""
    return _cli()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared data folder (skips with a message when absent)."""
    d = Path(os.environ.get("FEMU_SHARED_DATA", REPO.parent / "shared" / "data"))
    if not d.is_dir():
        pytest.skip(f"shared data folder {d} absent: tests on real data skipped")
    return d
