"""Digital image correlation: ``femu dic REF DEF`` on NumPy images (or PNG/TIFF/DICOM files),
with the same options and defaults; the measured field and its covariance as arrays."""

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np

from . import _femu, results
from ._progress import reporter
from ._scratch import Scratch


@dataclass
class DicResult:
    """What ``femu dic`` measured."""

    #: ``summary.json``: the options chosen, convergence, quality.
    report: results.DicReport
    #: The field of ``field.csv`` (model frame, mm): ``x, y, ux, uy, sx, sy, w`` and the
    #: same points in pixels ``x_px, y_px, ux_px, uy_px``; one array per column.
    field: Dict[str, np.ndarray]
    #: The DIC mesh's nodes: ``x_px`` (nodes x 2), ``u_px`` (nodes x 2), ``sd_px`` (standard
    #: deviations of ux, uy), ``corr_xy``, ``w`` (1: every element around it trusted) and the
    #: element connectivity ``elements``.
    nodes: Dict[str, np.ndarray]
    #: The nodal covariance (px²) in compressed columns (``col_ptr``, ``row_idx``,
    #: ``values``, order ``n``; equation ``2 node + c``, c = 0 for ux, 1 for uy).
    covariance_csc: Dict[str, Any]
    #: The output folder, when one was asked for.
    folder: Optional[Path]

    def covariance(self):
        """The nodal covariance as a ``scipy.sparse.csc_matrix`` (px²; both triangles, on the
        pattern of the Gauss–Newton matrix)."""
        from scipy.sparse import csc_matrix

        c = self.covariance_csc
        n = c["n"]
        return csc_matrix((c["values"], c["row_idx"], c["col_ptr"]), shape=(n, n))

    def field_table(self):
        """The field as a DataFrame (the columns of ``field.csv``)."""
        from . import _tables

        cols = ["x", "y", "ux", "uy", "sx", "sy", "w"]
        n = len(self.field["x"])
        rows = [{c: float(self.field[c][k]) for c in cols} for k in range(n)]
        return _tables.frame(rows, cols)

    def to_field(self):
        """The measured field for an identification (:class:`femu.Field`, weights from the
        standard deviations; untrusted points (w = 0) left out)."""
        from .identify import Field

        keep = self.field["w"] > 0
        f = {k: np.asarray(v)[keep] for k, v in self.field.items()}
        return Field(f["x"], f["y"], f["ux"], f["uy"], sx=f["sx"], sy=f["sy"])


def dic(reference, deformed, out=None, progress: Any = False, **options) -> DicResult:
    """Correlates ``reference`` and ``deformed`` as ``femu dic`` does.

    Images are paths (PNG, TIFF, DICOM) or two-dimensional arrays of grey levels on the 0–255
    scale (``uint16`` arrays are divided by 257 as 16-bit files are; convert colour to grey
    first). ``out``: the output folder (``field.csv``, ``nodes.csv``, ``covariance.mtx``, maps,
    ``summary.json``); without it a temporary folder is used and removed.

    Options (the command's, same defaults): ``roi=(x, y, w, h)`` or ``mask`` (path or array,
    non-zero inside), ``element`` (px; default chosen from the speckle), ``tolerance=1e-3``,
    ``acceleration``, ``max_iterations=100``, ``brightness="global"`` (``"none"``,
    ``"per-element"``), ``regularization`` (``None``/``"auto"``, ``"off"`` or px),
    ``levels``, ``fft=True``, ``flag_factor=3.0``, ``min_zncc=0.5``, ``pixel_size`` (mm, one
    value or (x, y)), ``origin=(0, 0)`` (px), ``y_up``, ``x_left``, ``grid`` (px),
    ``frame_ref``, ``frame_def``, ``figures=True``.
    """
    if isinstance(reference, os.PathLike):
        reference = os.fspath(reference)
    if isinstance(deformed, os.PathLike):
        deformed = os.fspath(deformed)
    if "regularization" in options and options["regularization"] in ("auto",):
        options["regularization"] = None
    with Scratch(out) as folder:
        d = _femu.dic(
            reference, deformed, os.fspath(folder), reporter=reporter(progress), **options
        )
    return DicResult(
        report=results.parse(results.DicReport, d["report"]),
        field=dict(d["field"]),
        nodes=dict(d["nodes"]),
        covariance_csc=dict(d["covariance"]),
        folder=Path(out) if out is not None else None,
    )


def read_image(path, frame: int = 0):
    """An image file as femu reads it: a float array of grey levels (0–255; colour as BT.601
    luminance) and the pixel size ``(dx, dy)`` in mm when a DICOM header gives it."""
    return _femu.read_image(os.fspath(path), frame)
