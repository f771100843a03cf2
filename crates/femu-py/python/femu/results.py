"""femu's typed results in Python: dataclasses that mirror the serde structs the steps return
and write as ``summary.json`` (``femu_study::steps::*``, ``femu_identify::campaign``,
``femu_mech::solver``, ``femu_dic::command``), built from the JSON text the extension hands
over — the numbers exactly as ``femu run`` computed and wrote them.

A field the Rust struct has and the mirror does not is kept in the object's ``extra`` dict (and
``unmirrored(obj)`` lists them: the package's tests require none, so that the mirror follows the
structs). A JSON ``null`` where a float is expected (a non-finite number: an infinite standard
deviation, a failed Newton trial) reads back as NaN, as ``femu_study::json`` reads it.
"""

import dataclasses
import json
import math
import sys
import typing
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from . import _tables


def _convert(tp: Any, value: Any) -> Any:
    """``value`` (parsed JSON) as the type ``tp``."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is typing.Union:  # Optional[X]
        if value is None:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(inner[0], value)
    if tp is float:
        return math.nan if value is None else float(value)
    if tp in (int, str, bool) or tp is Any:
        return value
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value)
    if origin in (list, List):
        return [_convert(args[0], v) for v in value]
    if origin in (dict, Dict):
        return {k: _convert(args[1], v) for k, v in value.items()}
    if origin in (tuple, Tuple):
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v) for v in value)
        return tuple(_convert(a, v) for a, v in zip(args, value))
    return value


def from_dict(cls, data: Dict[str, Any]):
    """An instance of the dataclass ``cls`` from the parsed JSON object ``data``; keys the
    dataclass does not declare go to its ``extra``."""
    hints = typing.get_type_hints(cls, vars(sys.modules[cls.__module__]))
    names = {f.name for f in dataclasses.fields(cls) if f.init and f.name != "extra"}
    kwargs = {k: _convert(hints[k], v) for k, v in data.items() if k in names}
    obj = cls(**kwargs)
    obj.extra = {k: v for k, v in data.items() if k not in names}
    return obj


def unmirrored(obj: Any, path: str = "") -> List[str]:
    """The fields of the Rust structs behind ``obj`` (and the objects it holds) that the
    dataclasses do not mirror, as dotted paths."""
    out: List[str] = []
    if dataclasses.is_dataclass(obj):
        out += [f"{path}{type(obj).__name__}.{k}" for k in getattr(obj, "extra", {})]
        for f in dataclasses.fields(obj):
            if f.name != "extra":
                out += unmirrored(getattr(obj, f.name), f"{path}{type(obj).__name__}.")
    elif isinstance(obj, (list, tuple)):
        for v in obj[:1]:
            out += unmirrored(v, path)
    elif isinstance(obj, dict):
        for v in list(obj.values())[:1]:
            out += unmirrored(v, path)
    return sorted(set(out))


def _extra():
    return field(default_factory=dict, repr=False, compare=False)


# --- a run's record (steps.json) -------------------------------------------------------------


@dataclass
class StepRecord:
    """One step of a run: ``femu_study::steps::record::StepRecord``."""

    name: str
    status: str
    folder: Optional[str]
    seconds: float
    error: Optional[str]
    extra: Dict[str, Any] = _extra()


@dataclass
class RunRecord:
    """``steps.json``: ``femu_study::steps::record::RunRecord``."""

    femu_version: str
    command: str
    study: str
    started_unix_s: int
    threads: int
    os: str
    steps: List[StepRecord]
    total_seconds: float
    extra: Dict[str, Any] = _extra()


# --- forward solves (forward/TEST/summary.json) -----------------------------------------------


@dataclass
class IterationRecord:
    """One Newton iteration: ``femu_mech::solver::IterationRecord``."""

    iteration: int
    residual_norm: float
    reference_force: float
    energy_norm: float
    step_length: float
    max_correction: float
    extra: Dict[str, Any] = _extra()


@dataclass
class IncrementRecord:
    """One load increment: ``femu_mech::solver::IncrementRecord``."""

    increment: int
    #: Load factor reached (or tried); ``lambda`` in the JSON.
    lambda_: float
    dlambda: float
    converged: bool
    failure: Optional[str]
    iterations: List[IterationRecord]
    #: Per rigid body: (travel mm, force N/mm).
    bodies: List[Tuple[float, float]]
    extra: Dict[str, Any] = _extra()


@dataclass
class SolveReport:
    """The Newton solve: ``femu_mech::solver::SolveReport``."""

    increments: List[IncrementRecord]
    converged_increments: int
    cutbacks: int
    newton_iterations: int
    factorizations: int
    equations: int
    matrix_nonzeros: int
    #: ``lambda`` in the JSON.
    lambda_: float
    reaction_total: Tuple[float, float]
    wall_time_s: float
    setup_time_s: float
    assembly_time_s: float
    factorization_time_s: float
    triangular_solve_time_s: float
    warm_start: bool
    factorization: Optional[str]
    extra: Dict[str, Any] = _extra()

    def newton_table(self):
        """Every Newton iteration of every increment (a DataFrame with pandas)."""
        rows = []
        for inc in self.increments:
            for it in inc.iterations:
                rows.append(
                    {
                        "increment": inc.increment,
                        "load_factor": inc.lambda_,
                        "converged": inc.converged,
                        **{k: getattr(it, k) for k in _ITERATION_COLUMNS},
                    }
                )
        return _tables.frame(rows, ["increment", "load_factor", "converged", *_ITERATION_COLUMNS])


_ITERATION_COLUMNS = [
    "iteration",
    "residual_norm",
    "reference_force",
    "energy_norm",
    "step_length",
    "max_correction",
]


@dataclass
class MaterialSummary:
    """``femu_study::steps::solve::MaterialSummary``."""

    name: str
    c10_kpa: Optional[float]
    d_per_mpa: Optional[float]
    elements: int
    law: str = ""
    parameters: Dict[str, float] = field(default_factory=dict)
    extra: Dict[str, Any] = _extra()


@dataclass
class RigidBodySummary:
    """``femu_study::steps::solve::RigidBodySummary``."""

    name: str
    body: str
    control: str
    travel_mm: float
    force_n_per_mm: float
    active_nodes: int
    max_penetration_mm: float
    penetration_limit_mm: float
    penalty_n_per_mm: float
    augmentations: int
    extra: Dict[str, Any] = _extra()


@dataclass
class SolveTimings:
    """``femu_study::steps::solve::SolveTimings`` (s)."""

    read_s: float
    setup_s: float
    solve_s: float
    assembly_s: float
    factorization_s: float
    triangular_solve_s: float
    output_s: float
    total_s: float
    extra: Dict[str, Any] = _extra()


@dataclass
class SolveSummary:
    """A forward solve's ``summary.json``: ``femu_study::steps::solve::SolveSummary``."""

    femu_version: str
    command: str
    input: str
    status: str
    error: Optional[str]
    nodes: int
    elements: int
    element_types: Dict[str, int]
    materials: List[MaterialSummary]
    prescribed_dofs: int
    pressure_faces: int
    rigid_bodies: List[RigidBodySummary]
    load_factor: float
    max_displacement_mm: float
    reaction_force_total_n_per_mm: Tuple[float, float]
    increments: int
    newton_iterations: int
    cutbacks: int
    #: ``femu_mech::SolverOptions``.
    solver_options: Dict[str, Any]
    report: SolveReport
    timings: SolveTimings
    peak_memory_mb: Optional[float]
    #: Labels of nodes no element uses (held fixed by the solver).
    unused_nodes: List[int] = field(default_factory=list)
    extra: Dict[str, Any] = _extra()

    def newton_table(self):
        """The Newton history (see :meth:`SolveReport.newton_table`)."""
        return self.report.newton_table()


# --- sensitivity (sensitivity/summary.json) ----------------------------------------------------


@dataclass
class SensitivityReport:
    """The direct differentiation: ``femu_mech::sensitivity::SensitivityReport``."""

    parameters: int
    active_constraints: int
    back_substitutions: int
    refactorized: bool
    max_relative_residual: float
    refinement_steps: int
    wall_time_s: float
    assembly_time_s: float
    factorization_time_s: float
    triangular_solve_time_s: float
    residual_time_s: float
    extra: Dict[str, Any] = _extra()


@dataclass
class TestSummary:
    """One test's sensitivities: ``femu_study::steps::sensitivity::TestSummary``."""

    __test__ = False  # not a pytest class

    test: str
    solve_time_s: float
    sensitivity_time_s: float
    sensitivity_over_solve: float
    newton_iterations: int
    max_displacement_mm: float
    #: The seed's Eq. 3 per parameter.
    sensitivity_index: List[Tuple[str, float]]
    direct_differentiation: SensitivityReport
    finite_difference_max_relative_difference: Optional[List[Tuple[str, float]]]
    extra: Dict[str, Any] = _extra()


@dataclass
class Identifiability:
    """``femu_identify::fisher::Identifiability``: Cramér–Rao relative standard deviations,
    correlations and singular values of the (log-)parameters."""

    names: List[str]
    relative_sd: List[float]
    correlation: List[List[float]]
    singular_values: List[float]
    condition: float
    extra: Dict[str, Any] = _extra()

    def table(self):
        """The predicted relative standard deviation of each parameter."""
        rows = [{"parameter": n, "relative_sd": s} for n, s in zip(self.names, self.relative_sd)]
        return _tables.frame(rows, ["parameter", "relative_sd"], index="parameter")

    def correlation_table(self):
        return _tables.square(self.correlation, self.names)


@dataclass
class Ranking:
    """One measurement's predicted identifiability: ``...::sensitivity::Ranking``."""

    measurement: str
    grouping: str
    worst_c10_relative_sd: float
    worst_d_relative_sd: float
    condition: float
    identifiability: Identifiability
    worst_relative_sd: List[Tuple[str, float]] = field(default_factory=list)
    extra: Dict[str, Any] = _extra()


@dataclass
class ParameterEntry:
    """A model parameter as its law declares it: ``femu_study::output::ParameterEntry``."""

    name: str
    kind: str
    material: str
    law: str
    value: float
    unit: str
    key: str
    shown: float
    shown_unit: str
    log_scale: bool
    extra: Dict[str, Any] = _extra()


@dataclass
class SensitivitySummary:
    """``sensitivity/summary.json``: ``femu_study::steps::sensitivity::SensitivitySummary``."""

    command: str
    version: str
    elements: int
    nodes: int
    element: str
    parameters: List[Tuple[str, float]]
    tests: List[TestSummary]
    grid_points: int
    grid_points_in_tissue: int
    grid_spacing_mm: float
    noise_sigma_mm: float
    ranking: List[Ranking]
    finding: List[str]
    wall_time_s: float
    failed_tests: List[Tuple[str, str]] = field(default_factory=list)
    law_parameters: List[ParameterEntry] = field(default_factory=list)
    extra: Dict[str, Any] = _extra()

    def identifiability_table(self):
        """The test ranking (best first per grouping): worst predicted relative sd of C10 and
        D, condition number."""
        cols = [
            "measurement",
            "grouping",
            "worst_c10_relative_sd",
            "worst_d_relative_sd",
            "condition",
        ]
        return _tables.frame([{c: getattr(r, c) for c in cols} for r in self.ranking], cols)

    def index_table(self):
        """The seed's Eq. 3 index of every parameter (rows) for every test (columns)."""
        names = [n for n, _ in self.parameters]
        rows = []
        for k, n in enumerate(names):
            row = {"parameter": n}
            for t in self.tests:
                row[t.test] = t.sensitivity_index[k][1]
            rows.append(row)
        return _tables.frame(rows, ["parameter", *[t.test for t in self.tests]], index="parameter")


# --- identification (identify/GROUPING/summary.json) ----------------------------------------


@dataclass
class LmStep:
    """One optimizer iteration: ``femu_identify::fit::LmStep``."""

    iteration: int
    cost: float
    damping: float
    accepted: bool
    max_step: float
    failure: Optional[str]
    extra: Dict[str, Any] = _extra()


@dataclass
class FitResult:
    """One optimizer run: ``femu_identify::fit::FitResult`` (parameters in model units)."""

    theta: List[float]
    start: List[float]
    cost: float
    iterations: int
    forward_solves: int
    jacobians: int
    converged: bool
    reason: str
    history: List[LmStep]
    wall_time_s: float
    data: int
    extra: Dict[str, Any] = _extra()

    def cost_history(self):
        """The cost after each iteration (accepted or not)."""
        cols = ["iteration", "cost", "damping", "accepted", "max_step", "failure"]
        return _tables.frame([{c: getattr(h, c) for c in cols} for h in self.history], cols)


@dataclass
class StartRecord:
    """One start: ``femu_identify::campaign::StartRecord``."""

    repeat: int
    start: int
    theta_start: List[float]
    result: Optional[FitResult]
    error: Optional[str]
    extra: Dict[str, Any] = _extra()


@dataclass
class Estimate:
    """An identified parameter: ``femu_identify::campaign::Estimate`` (model units)."""

    name: str
    reference: Optional[float]
    identified: float
    relative_error: Optional[float]
    relative_sd: float
    ci95: Tuple[float, float]
    mean_relative_error: Optional[float]
    sd_relative_error: Optional[float]
    sd_identified_relative: Optional[float]
    #: Monte Carlo: the largest relative error over the repeats, and how often the 95 %
    #: interval covered the truth.
    max_relative_error: Optional[float] = None
    coverage95: Optional[float] = None
    #: The mesh's bias of this parameter (discretization check), and the interval from the
    #: noise alone (before widening for that bias).
    discretization_bias: Optional[float] = None
    ci95_noise: Optional[Tuple[float, float]] = None
    #: On a measured field (``femu_identify::misfit_intervals``): the Fisher sd, the Birge ratio
    #: √(χ²/ν), the depth-block jackknife sd, and which of them set ``relative_sd``.
    sd_fisher: Optional[float] = None
    birge_ratio: Optional[float] = None
    sd_jackknife: Optional[float] = None
    width_from: Optional[str] = None
    extra: Dict[str, Any] = _extra()


@dataclass
class MemberSummary:
    material: int
    kind: str
    extra: Dict[str, Any] = _extra()


@dataclass
class FreeParameterSummary:
    """``femu_study::steps::identify::FreeParameterSummary``."""

    name: str
    members: List[MemberSummary]
    lower: float
    upper: float
    #: The unit tables show it in (C10 in kPa, D in MPa⁻¹) and the factor from the model unit.
    unit: str = ""
    unit_factor: float = 1.0
    extra: Dict[str, Any] = _extra()


@dataclass
class InformationShare:
    """``femu_identify::joint::InformationShare``: a measurement's share of the information
    per free parameter, and the relative sd it would give alone."""

    measurement: str
    rows: int
    share: List[float]
    alone_relative_sd: List[float]
    extra: Dict[str, Any] = _extra()


@dataclass
class MeasurementSummary:
    """One measurement of an identification: ``femu_study::steps::identify::MeasurementSummary``."""

    name: str
    label: str
    source: str
    sigma_mm: Optional[float]
    points_in_tissue: int
    points_masked: int
    information: InformationShare
    extra: Dict[str, Any] = _extra()


@dataclass
class LevelRecord:
    """A finer mesh of the discretization check: ``femu_identify::discretization::LevelRecord``."""

    ratio: float
    elements: int
    field_change: float
    change_to_finest: float
    shift: Optional[List[float]]
    extra: Dict[str, Any] = _extra()


@dataclass
class DiscretizationCheck:
    """How much the mesh biases the identified parameters:
    ``femu_identify::discretization::DiscretizationCheck``."""

    status: str
    elements: int
    levels: List[LevelRecord]
    rate: float
    rate_observed: bool
    fitted_rate: Optional[float]
    rate_misfit: float
    bias: List[float]
    bias_over_sd: List[float]
    threshold: float
    recommended_elements: Optional[int]
    message: str
    extra: Dict[str, Any] = _extra()


_ESTIMATE_COLUMNS = [
    "name",
    "reference",
    "identified",
    "relative_error",
    "relative_sd",
    "ci95_low",
    "ci95_high",
    "mean_relative_error",
    "sd_relative_error",
    "sd_identified_relative",
]


@dataclass
class IdentificationSummary:
    """``identify/GROUPING/summary.json``:
    ``femu_study::steps::identify::IdentificationSummary``."""

    command: str
    version: str
    test: str
    optimizer: str
    grouped: bool
    elements: int
    measured: str
    points_in_tissue: int
    points_masked: int
    noise_sigma_mm: float
    free_parameters: List[FreeParameterSummary]
    parameters: List[Estimate]
    correlation: List[List[float]]
    best_cost: float
    starts_per_repeat: int
    repeats: int
    travel_term: Optional[Tuple[Optional[float], float]]
    coarse_elements: Optional[int]
    refinement_forward_solves: List[int]
    forward_solves_per_start: List[int]
    starts: List[StartRecord]
    wall_time_s: float
    #: Why the values or intervals may mean nothing (a start at a bound, an infinite sd).
    warnings: List[str] = field(default_factory=list)
    interrupted: Optional[str] = None
    #: Each measurement fitted, its points and its share of the information.
    measurements: List[MeasurementSummary] = field(default_factory=list)
    #: The discretization check (None when switched off).
    discretization: Optional[DiscretizationCheck] = None
    #: How the misfit was weighted: "one sigma" (virtual), "per point" (a file's sx, sy or w),
    #: "full covariance" (weighted FEMU with the DIC's covariance).
    weighting: str = ""
    #: The loss on the whitened residuals: ``"squared"`` or ``{"huber": {"k": 1.345}}``.
    loss: Any = "squared"
    extra: Dict[str, Any] = _extra()

    def table(self):
        """The identified parameters: values, Eq. 4 errors, relative sd, 95 % intervals (the
        columns of ``parameters.csv``; model units: C10 in MPa, D in MPa⁻¹)."""
        rows = []
        for p in self.parameters:
            row = {c: getattr(p, c, None) for c in _ESTIMATE_COLUMNS}
            row["ci95_low"], row["ci95_high"] = p.ci95
            rows.append(row)
        return _tables.frame(rows, _ESTIMATE_COLUMNS, index="name")

    def correlation_table(self):
        """The correlations of the identified (log-)parameters."""
        return _tables.square(self.correlation, [p.name for p in self.parameters])

    @property
    def best(self) -> FitResult:
        """The best start of the first repeat (the optimum the estimates are of, before a
        multilevel refinement)."""
        fits = [s.result for s in self.starts if s.repeat == 0 and s.result is not None]
        return min(fits, key=lambda r: r.cost)

    def cost_history(self):
        """The best start's optimizer history."""
        return self.best.cost_history()

    def starts_table(self):
        """Every start of every repeat: cost, iterations, forward solves, the error if any."""
        rows = []
        for s in self.starts:
            r = s.result
            rows.append(
                {
                    "repeat": s.repeat,
                    "start": s.start,
                    "cost": r.cost if r else math.nan,
                    "iterations": r.iterations if r else None,
                    "forward_solves": r.forward_solves if r else None,
                    "converged": r.converged if r else False,
                    "error": s.error,
                }
            )
        cols = ["repeat", "start", "cost", "iterations", "forward_solves", "converged", "error"]
        return _tables.frame(rows, cols)


# --- DIC (summary.json of femu dic) --------------------------------------------------------


@dataclass
class DicSummary:
    """The correlation: ``femu_dic::output::DicSummary``."""

    elements: int
    nodes: int
    element_size_px: int
    iterations: int
    converged: bool
    last_increment_px: float
    residual_rms: float
    residual_percent_of_dynamic: float
    flagged_elements: int
    initial_shift_px: Tuple[int, int]
    mean_u_px: Tuple[float, float]
    std_u_px: Tuple[float, float]
    levels: List[Dict[str, Any]]
    timings: Dict[str, Any]
    extra: Dict[str, Any] = _extra()


@dataclass
class QualitySummary:
    """``femu_dic::command::QualitySummary``."""

    trusted_elements: int
    untrusted: List[Tuple[str, int]]
    sd_median_px: Tuple[float, float]
    sd_p90_px: Tuple[float, float]
    residual_correlation_lags_px: Tuple[int, int]
    criteria: Dict[str, Any]
    extra: Dict[str, Any] = _extra()


@dataclass
class DicReport:
    """``femu dic``'s ``summary.json``: ``femu_dic::command::DicReport``."""

    femu_version: str
    command: str
    #: The job: images, options (``femu_dic::command::DicJob``).
    job: Dict[str, Any]
    image_size_px: Tuple[int, int]
    pixel_size: Optional[Dict[str, Any]]
    model_frame: Dict[str, Any]
    #: How the element size and regularization were chosen (``femu_dic::auto::Choice``).
    choice: Dict[str, Any]
    result: DicSummary
    quality: QualitySummary
    grid_points: int
    outputs: List[str]
    warnings: List[str]
    advice: Optional[str]
    wall_time_s: float
    extra: Dict[str, Any] = _extra()


# JSON keys that are Python keywords.
def _rename_lambda(data: Any) -> Any:
    if isinstance(data, dict):
        return {("lambda_" if k == "lambda" else k): _rename_lambda(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_rename_lambda(v) for v in data]
    return data


def parse(cls, text: str):
    """``cls`` from the JSON text of its Rust struct."""
    return from_dict(cls, _rename_lambda(json.loads(text)))
