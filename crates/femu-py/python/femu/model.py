"""Models and forward solves: the built-in thigh, a label image (a NumPy array) or a deck;
a loading test solved for given parameters with its fields as arrays; the exact parameter
sensitivities; conversion to PyVista and meshio."""

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _femu, _tables, results
from ._progress import reporter

TestArg = Union[str, Mapping[str, Any]]


class Model:
    """A built model, unloaded: mesh, regions and materials, the skin the tests load.

    ``Model.thigh()``, ``Model.from_labels(array, ...)``, ``Model.from_deck(path)`` or
    ``Study.model()``. Parameters are in model units (C10 in MPa, D in MPa⁻¹), named as femu
    names them (``C10_FAT``, ``D_QUADRICEPS``)."""

    def __init__(self, inner: "_femu.Model", study: "_femu.Study"):
        self._inner = inner
        # The checked study the model was built from: its tests are the ones solved by name.
        self._study = study

    @classmethod
    def _of(cls, data: Dict[str, Any]) -> "Model":
        """The model of a study given as a dict of the study file's tables."""
        study = _femu.Study.from_dict(data, None)
        return cls(_femu.model_of_study(study, reporter(False)), study)

    # --- building -------------------------------------------------------------------------

    @classmethod
    def thigh(
        cls,
        elements: Optional[int] = None,
        size_mm: Optional[float] = None,
        element: str = "cpe4h",
        dimensions: Optional[Mapping[str, Any]] = None,
        materials: Optional[Mapping[str, Mapping[str, float]]] = None,
    ) -> "Model":
        """The built-in parametric thigh (``[thigh]`` dimensions, ``[materials.REGION]``
        overrides of Table 1, e.g. ``{"fat": {"c10_kpa": 1.0}}``)."""
        model: Dict[str, Any] = {"element": element}
        if elements is not None:
            model["elements"] = elements
        if size_mm is not None:
            model["size_mm"] = size_mm
        data: Dict[str, Any] = {"model": model}
        if dimensions:
            data["thigh"] = dict(dimensions)
        if materials:
            data["materials"] = {k: dict(v) for k, v in materials.items()}
        return cls._of(data)

    @classmethod
    def from_labels(
        cls,
        labels: Any,
        pixel_size_mm: float,
        map: Union[str, Mapping[int, str]],
        bone: Sequence[int] = (7,),
        background: Sequence[int] = (0,),
        size_mm: Optional[float] = None,
        element: str = "cpe4h",
        min_island_mm2: Optional[float] = None,
        materials: Optional[Mapping[str, Mapping[str, float]]] = None,
    ) -> "Model":
        """A segmented slice meshed as ``femu mesh labels`` meshes it: ``labels`` an integer
        array (row 0 at the top, as an image is stored), ``map`` ``{1: "fat", 2:
        "quadriceps", ...}`` or ``"1=fat,2=quadriceps,..."``."""
        if not isinstance(map, str):
            map = ",".join(f"{int(k)}={v}" for k, v in map.items())
        entry: Dict[str, Any] = {
            "image": "(NumPy array)",
            "map": map,
            "bone": [int(b) for b in bone],
            "background": [int(b) for b in background],
            "pixel_size_mm": float(pixel_size_mm),
        }
        if min_island_mm2 is not None:
            entry["min_island_mm2"] = float(min_island_mm2)
        model: Dict[str, Any] = {"element": element}
        if size_mm is not None:
            model["size_mm"] = float(size_mm)
        data: Dict[str, Any] = {"model": model, "labels": entry}
        if materials:
            data["materials"] = {k: dict(v) for k, v in materials.items()}
        study = _femu.Study.from_dict(data, None)
        return cls(_femu.model_from_label_array(study, labels), study)

    @classmethod
    def from_deck(
        cls,
        path: Union[str, "os.PathLike[str]"],
        materials: Optional[Mapping[str, Mapping[str, float]]] = None,
    ) -> "Model":
        """An Abaqus/CalculiX contention deck (its ``*DLOAD`` faces are the skin)."""
        data: Dict[str, Any] = {"model": {"deck": os.path.abspath(os.fspath(path))}}
        if materials:
            data["materials"] = {k: dict(v) for k, v in materials.items()}
        return cls._of(data)

    # --- the mesh ---------------------------------------------------------------------------

    @property
    def nodes(self) -> np.ndarray:
        """Reference coordinates (mm), nodes x 2."""
        return self._inner.nodes

    @property
    def elements(self) -> np.ndarray:
        """Connectivity (node indices from 0), elements x 4; ``-1`` pads a triangle."""
        return self._inner.elements

    @property
    def element_types(self) -> List[str]:
        return list(self._inner.element_types)

    @property
    def element_regions(self) -> np.ndarray:
        """Region index (into :attr:`region_names`) of each element."""
        return self._inner.element_regions

    @property
    def region_names(self) -> List[str]:
        return list(self._inner.region_names)

    @property
    def skin(self) -> np.ndarray:
        """The skin faces as (element, face) pairs."""
        return self._inner.skin

    @property
    def source(self) -> str:
        return self._inner.source

    @property
    def tests(self) -> List[str]:
        """The names of the loading tests of the study the model was built from: the tests
        :meth:`solve` and :meth:`sensitivities` take by name."""
        return list(self._study.tests)

    @property
    def parameters(self) -> Dict[str, float]:
        """Every material parameter (model units), in the order of the sensitivities."""
        return {p[0]: p[1] for p in self._inner.parameters()}

    def parameter_table(self):
        """Name, value, unit, law parameter and material of every parameter."""
        cols = ["name", "value", "unit", "law_parameter", "material"]
        rows = [dict(zip(cols, p)) for p in self._inner.parameters()]
        return _tables.frame(rows, cols, index="name")

    def triangles(self) -> np.ndarray:
        """The elements as triangles (a quad as two), for ``matplotlib.tri.Triangulation``."""
        e = self.elements
        tri = e[:, [0, 1, 2]]
        quads = e[e[:, 3] >= 0]
        return np.concatenate([tri, quads[:, [0, 2, 3]]])

    # --- solving ----------------------------------------------------------------------------

    def _test(self, test: TestArg) -> Tuple[Any, int]:
        """The study holding ``test`` and its index: one of the model's study's tests by name
        (``compression``, ``compression-anterior``), or a ``[[test]]`` entry given as a dict
        (``{"kind": "indentation", "radius_mm": 5}``)."""
        if isinstance(test, str):
            for k, n in enumerate(self.tests):
                if n.lower() == test.lower() or n.split("-")[0].lower() == test.lower():
                    return self._study, k
            test = {"kind": test}
        return _femu.Study.from_dict({"test": [dict(test)]}, None), 0

    def solve(
        self,
        test: TestArg = "compression",
        parameters: Optional[Mapping[str, float]] = None,
        progress: Any = False,
    ) -> "Solution":
        """Solves a loading test (a name of the study's tests, or a ``[[test]]`` dict) with
        ``parameters`` (``{"C10_FAT": 1.0e-3}``, model units) over the model's own; returns
        the displacements, reactions and element fields as arrays."""
        study, k = self._test(test)
        d = self._inner.solve(study, k, dict(parameters or {}), reporter(progress))
        return Solution(
            model=self,
            test=d["test"],
            u=d["u"],
            reactions=d["reactions"],
            log_strain=d["log_strain"],
            stress=d["stress"],
            volume_ratio=d["volume_ratio"],
            bodies=json.loads(d["bodies"]),
            report=results.parse(results.SolveReport, d["report"]),
        )

    def sensitivities(
        self,
        test: TestArg = "compression",
        parameters: Optional[Mapping[str, float]] = None,
        progress: Any = False,
    ) -> "Sensitivities":
        """The exact sensitivities of a loading test's displacements to every material
        parameter (direct differentiation of the discrete equilibrium, one back-substitution
        per parameter): ``du[n, c, k] = ∂u_c(node n)/∂θ_k``."""
        study, k = self._test(test)
        d = self._inner.sensitivities(study, k, dict(parameters or {}), reporter(progress))
        return Sensitivities(
            model=self,
            test=d["test"],
            names=list(d["names"]),
            values=np.asarray(d["values"]),
            u=d["u"],
            du=d["du"],
            maps=d["maps"],
            index=np.asarray(d["index"]),
            newton_iterations=d["newton_iterations"],
            report=results.parse(results.SensitivityReport, d["report"]),
        )

    def write(self, out: Union[str, "os.PathLike[str]"]) -> Dict[str, Any]:
        """Writes the model folder of ``femu run`` (``mesh.inp``, ``mesh.vtu``,
        ``regions.png``, ``quality.csv``, ``summary.json``); returns its summary."""
        return json.loads(self._inner.write(os.fspath(out)))

    # --- conversion ------------------------------------------------------------------------

    def to_meshio(self, point_data=None, cell_data=None):
        """The mesh as a ``meshio.Mesh`` (z = 0), with optional point and cell data."""
        import meshio

        pts = np.column_stack([self.nodes, np.zeros(len(self.nodes))])
        e = self.elements
        quads = e[:, 3] >= 0
        cells, order = [], []
        if quads.any():
            cells.append(("quad", e[quads]))
            order.append(np.nonzero(quads)[0])
        if (~quads).any():
            cells.append(("triangle", e[~quads][:, :3]))
            order.append(np.nonzero(~quads)[0])
        cd = {"region": [self.element_regions[o] for o in order]}
        for name, values in (cell_data or {}).items():
            cd[name] = [np.asarray(values)[o] for o in order]
        return meshio.Mesh(pts, cells, point_data=dict(point_data or {}), cell_data=cd)

    def to_pyvista(self, point_data=None, cell_data=None):
        """The mesh as a ``pyvista.UnstructuredGrid`` (z = 0), with optional point and cell
        data (``region`` always)."""
        import pyvista as pv

        pts = np.column_stack([self.nodes, np.zeros(len(self.nodes))])
        e = self.elements
        quads = e[:, 3] >= 0
        sizes = np.where(quads, 4, 3)
        cells = np.concatenate(
            [np.concatenate([[s], row[:s]]) for s, row in zip(sizes, e)]
        ).astype(np.int64)
        types = np.where(quads, 9, 5).astype(np.uint8)  # VTK_QUAD, VTK_TRIANGLE
        grid = pv.UnstructuredGrid(cells, types, pts)
        grid.cell_data["region"] = self.element_regions
        for name, values in (point_data or {}).items():
            grid.point_data[name] = np.asarray(values)
        for name, values in (cell_data or {}).items():
            grid.cell_data[name] = np.asarray(values)
        return grid

    def __repr__(self) -> str:
        return repr(self._inner)


@dataclass
class Solution:
    """A solved loading test: arrays over the model's nodes and elements."""

    model: Model
    test: str
    #: Nodal displacements (mm), nodes x 2.
    u: np.ndarray
    #: Reaction forces at the prescribed dofs (N per mm of thickness), nodes x 2.
    reactions: np.ndarray
    #: Logarithmic strain ``[LExx, LEyy, LEzz, LExy]`` per element.
    log_strain: np.ndarray
    #: Cauchy stress ``[Sxx, Syy, Szz, Sxy]`` per element (MPa).
    stress: np.ndarray
    #: J = det F per element.
    volume_ratio: np.ndarray
    #: Contact results per rigid body (travel, force, penetration, ...).
    bodies: List[Dict[str, Any]]
    #: The Newton history (``report.newton_table()``).
    report: results.SolveReport

    @property
    def deformed(self) -> np.ndarray:
        """Deformed node positions (mm)."""
        return self.model.nodes + self.u

    def newton_table(self):
        return self.report.newton_table()

    def _cell_data(self) -> Dict[str, np.ndarray]:
        return {"LE": self.log_strain, "S": self.stress, "J": self.volume_ratio}

    def to_pyvista(self):
        """The model with ``u`` (3 components, z = 0), LE, S and J, for PyVista."""
        u3 = np.column_stack([self.u, np.zeros(len(self.u))])
        return self.model.to_pyvista({"u": u3}, self._cell_data())

    def to_meshio(self):
        u3 = np.column_stack([self.u, np.zeros(len(self.u))])
        return self.model.to_meshio({"u": u3}, self._cell_data())


@dataclass
class Sensitivities:
    """The exact sensitivities of one test to every material parameter."""

    model: Model
    test: str
    names: List[str]
    #: The parameters' values (model units).
    values: np.ndarray
    #: The solution's nodal displacements (mm), nodes x 2.
    u: np.ndarray
    #: ``∂u/∂θ`` (mm per model unit), nodes x 2 x parameters.
    du: np.ndarray
    #: The seed's Eq. 3 map per node and parameter: ``θ_k |∂u_n/∂θ_k| / rms|u|``.
    maps: np.ndarray
    #: The seed's Eq. 3 index per parameter: ``‖θ_k ∂U/∂θ_k‖ / ‖U‖``.
    index: np.ndarray
    newton_iterations: int
    report: results.SensitivityReport

    def index_table(self):
        rows = [{"parameter": n, "index": s} for n, s in zip(self.names, self.index)]
        return _tables.frame(rows, ["parameter", "index"], index="parameter")
