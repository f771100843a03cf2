"""Identification from a measured field given as arrays, and femu's residual and exact
Jacobian as callables for SciPy's ``least_squares`` (or any other optimizer)."""

import os
from typing import Any, Optional, Sequence

import numpy as np

from . import _femu, results
from ._progress import reporter
from ._scratch import Scratch
from .field import Field
from .study import Study


def identify(
    study: Study,
    field: Field,
    out=None,
    grouped: Optional[bool] = None,
    progress: Any = True,
) -> results.IdentificationSummary:
    """Identifies the study's free parameters (its groups, fixed parameters, optimizer,
    starts) from ``field`` as ``femu identify STUDY --measured CSV`` does: the same optimum,
    intervals and correlations (from the residual variance). ``out``: the output folder
    (``parameters.csv``, ``starts.csv``, figures, ``summary.json``); without it a temporary one.
    Releases the GIL; Ctrl-C stops it at the next forward solve."""
    c = field.columns()
    with Scratch(out) as folder:
        text = _femu.identify_field(
            study._inner,
            c["x"],
            c["y"],
            c["ux"],
            c["uy"],
            os.fspath(folder),
            sx=c.get("sx"),
            sy=c.get("sy"),
            w=c.get("w"),
            weights=c.get("weights"),
            grouped=grouped,
            reporter=reporter(progress),
        )
    return results.parse(results.IdentificationSummary, text)


class LeastSquares:
    """femu's identification problem as a residual and its exact Jacobian
    (``femu_identify::fit::Problem``, what femu's optimizers minimize): the weighted residuals
    ``r(φ) = √w (u_model(θ) − u_measured)`` at the measured points in the tissue, in
    log-parameters ``φ = ln θ``, and ``J = ∂r/∂φ`` by direct differentiation.

    >>> p = femu.LeastSquares(study, field)
    >>> sol = scipy.optimize.least_squares(p.residual, p.x0, jac=p.jacobian, bounds=p.bounds)
    >>> theta = np.exp(sol.x)

    The residual and Jacobian at a point are computed together and kept, so SciPy's ``jac``
    call after ``fun`` at the same point costs nothing. Each forward solve starts from the last
    converged state. A forward solve that fails (Newton diverging at extreme parameters)
    raises :class:`femu.SolveError`, or returns NaN residuals with ``failed="nan"`` (SciPy's
    trust-region methods then shrink the step).
    """

    def __init__(
        self,
        study: Study,
        field: Optional[Field] = None,
        grouped: Optional[bool] = None,
        failed: str = "raise",
    ):
        if failed not in ("raise", "nan"):
            raise ValueError("failed: 'raise' or 'nan'")
        self.failed = failed
        if field is None:
            self._inner = _femu.least_squares(study._inner, grouped=grouped)
        else:
            c = field.columns()
            self._inner = _femu.least_squares(
                study._inner,
                c["x"],
                c["y"],
                c["ux"],
                c["uy"],
                sx=c.get("sx"),
                sy=c.get("sy"),
                w=c.get("w"),
                weights=c.get("weights"),
                grouped=grouped,
            )
        self._m: Optional[int] = None

    @property
    def names(self):
        """The free parameters (tied ones joined by ``+``)."""
        return list(self._inner.names)

    @property
    def reference(self) -> np.ndarray:
        """The study's values of the free parameters (model units)."""
        return np.asarray(self._inner.reference)

    @property
    def x0(self) -> np.ndarray:
        """``ln`` of the reference values: a start in log-parameters."""
        return np.log(self.reference)

    @property
    def bounds(self):
        """``(ln lower, ln upper)``: the bounds in log-parameters, as SciPy takes them."""
        return np.log(self._inner.lower), np.log(self._inner.upper)

    @property
    def points(self):
        """Measured points inside the tissue, and masked ones."""
        return self._inner.points

    @property
    def counts(self):
        """Forward solves and Jacobian evaluations so far."""
        return self._inner.counts

    def residual(self, phi: Sequence[float]) -> np.ndarray:
        """The weighted residuals at ``phi`` (log-parameters)."""
        phi = [float(v) for v in phi]
        try:
            r = np.asarray(self._inner.residual(phi))
        except _femu.SolveError:
            if self.failed == "raise" or self._m is None:
                raise
            return np.full(self._m, np.nan)
        self._m = len(r)
        return r

    def jacobian(self, phi: Sequence[float]) -> np.ndarray:
        """``∂r/∂φ`` at ``phi``: residuals x parameters."""
        return self._inner.jacobian([float(v) for v in phi])

    def cost(self, phi: Sequence[float]) -> float:
        """``½|r(φ)|²``, the cost femu minimizes (seed Eq. 2, weighted)."""
        r = self.residual(phi)
        return 0.5 * float(r @ r)

    def levenberg_marquardt(self, start: Optional[Sequence[float]] = None) -> results.FitResult:
        """femu's own Levenberg–Marquardt from ``start`` (model units; default the
        reference), as each start of an identification runs it."""
        s = None if start is None else [float(v) for v in start]
        return results.parse(results.FitResult, self._inner.levenberg_marquardt(s))
