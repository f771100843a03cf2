"""femu from Python: finite element model updating of thigh muscles and fat.

The same Rust libraries as the ``femu`` command (no numerics in Python), NumPy arrays in and
out:

- :class:`Study` — a study file, dict or the demo's study; ``run()`` it (``femu run``) or one
  ``step()``; typed results (:mod:`femu.results`) with pandas tables;
- :class:`Model` — the built-in thigh, a label image (array) or a deck; ``solve()`` a loading
  test, ``sensitivities()`` (exact, nodes x 2 x parameters), ``to_pyvista()``/``to_meshio()``;
- :func:`dic` — ``femu dic`` on NumPy images or files: the field and its covariance;
- :func:`identify` — identification from a :class:`Field` given as arrays;
  :class:`LeastSquares` — femu's residual and exact Jacobian for SciPy's ``least_squares``.

Errors are :class:`FemuError` subclasses with the command line's messages (file, line, key);
long calls release the GIL, show progress (tqdm) and stop on Ctrl-C (``KeyboardInterrupt``).
"""

from ._femu import (
    DicError,
    FemuError,
    IdentificationError,
    InputError,
    SolveError,
    StudyError,
    __version__,
)
from . import results
from .dic import DicResult, dic, read_image
from .identify import Field, LeastSquares, identify
from .model import Model, Sensitivities, Solution
from .study import RunResult, Study, demo

__all__ = [
    "__version__",
    "FemuError",
    "StudyError",
    "InputError",
    "SolveError",
    "DicError",
    "IdentificationError",
    "Study",
    "RunResult",
    "demo",
    "Model",
    "Solution",
    "Sensitivities",
    "dic",
    "DicResult",
    "read_image",
    "Field",
    "identify",
    "LeastSquares",
    "results",
]
