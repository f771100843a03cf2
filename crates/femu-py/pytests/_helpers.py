"""Helpers of the femu package's tests (fixtures are in conftest.py)."""

import math
import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]


def run_cli(cli: Path, *args, check: bool = True) -> subprocess.CompletedProcess:
    """Runs ``femu ARGS`` and returns the finished process (text output)."""
    p = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"femu {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def rust_e(value: float, digits: int) -> str:
    """``value`` as Rust's ``{:.DIGITSe}`` prints it (``8.011017628e-4``: no ``+``, no zero
    padding of the exponent)."""
    if math.isnan(value):
        return "NaN"
    mantissa, exponent = f"{value:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


#: Keys of femu's summaries that hold times, memory or the command's own name: the rest of the
#: numbers of two runs of the same work are equal.
VOLATILE = re.compile(r"(time|_s$|_over_solve$|seconds|memory|started|^command$|^input$|^measured$|^out$)")


def plain(obj):
    """A result object (dataclasses of femu.results) as the JSON its Rust struct writes:
    ``lambda_`` back to ``lambda``, the ``extra`` fields merged, NaN as ``None``."""
    import dataclasses

    if dataclasses.is_dataclass(obj):
        d = {}
        for f in dataclasses.fields(obj):
            if f.name == "extra":
                continue
            d["lambda" if f.name == "lambda_" else f.name] = plain(getattr(obj, f.name))
        d.update(getattr(obj, "extra", {}))
        return d
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, float) and math.isnan(obj):
        return None
    return obj


def differences(a, b, path="", volatile=VOLATILE):
    """Where the JSON values ``a`` and ``b`` differ (numbers compared exactly), keys matching
    ``volatile`` skipped."""
    out = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if volatile.search(k):
                continue
            if (k not in a or k not in b) and a.get(k) in (None, []) and b.get(k) in (None, []):
                continue  # an Option or a list that serde leaves out when None or empty
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'second' if k in b else 'first'}")
            else:
                out += differences(a[k], b[k], f"{path}.{k}", volatile)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: {len(a)} vs {len(b)} items")
        for k, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, f"{path}[{k}]", volatile)
    elif a != b:
        out.append(f"{path}: {a!r} vs {b!r}")
    return out
