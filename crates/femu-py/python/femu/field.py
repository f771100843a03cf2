"""A measured displacement field given as arrays, in the model frame."""

import os

import numpy as np

from . import _femu


class Field:
    """A measured displacement field (conventions.md): points ``x, y`` and displacements
    ``ux, uy`` in the model frame (mm), weighted by standard deviations ``sx, sy`` (mm), a
    weight ``w`` per point, or ``weights`` per component (points x 2, the inverse variances
    femu keeps); unweighted without any."""

    def __init__(self, x, y, ux, uy, sx=None, sy=None, w=None, weights=None):
        self.x, self.y, self.ux, self.uy = (np.asarray(v, dtype=float) for v in (x, y, ux, uy))
        self.sx = None if sx is None else np.asarray(sx, dtype=float)
        self.sy = None if sy is None else np.asarray(sy, dtype=float)
        self.w = None if w is None else np.asarray(w, dtype=float)
        self.weights = None if weights is None else np.asarray(weights, dtype=float)

    @classmethod
    def read(cls, path) -> "Field":
        """A measured-field CSV (``x,y,ux,uy[,sx,sy][,w]``, ``#`` comment lines), read by
        femu (``femu_identify::measured``; a bad row is an :class:`femu.InputError` naming its
        line)."""
        x, y, ux, uy, weights = _femu.read_field(os.fspath(path))
        return cls(x, y, ux, uy, weights=weights)

    def columns(self):
        """The columns femu takes (those given)."""
        c = dict(x=self.x, y=self.y, ux=self.ux, uy=self.uy)
        for k in ("sx", "sy", "w", "weights"):
            if getattr(self, k) is not None:
                c[k] = getattr(self, k)
        return c

    def __len__(self) -> int:
        return len(self.x)

    def __repr__(self) -> str:
        given = [k for k in ("sx", "sy", "w", "weights") if getattr(self, k) is not None]
        return f"femu.Field({len(self)} points, {', '.join(given) or 'unweighted'})"
