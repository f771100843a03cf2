"""Studies: a study file (or a dict, or the demo's study) checked by femu's one study schema,
run whole as ``femu run`` runs it or one step at a time, and the typed results of a run."""

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Optional, Union

from . import _femu, results
from ._progress import reporter
from .field import Field
from .model import Model

PathLike = Union[str, "os.PathLike[str]"]


class Study:
    """A checked study (``femu_study::schema::Study``) and its TOML text.

    Build one with :meth:`load` (a study file), :meth:`from_dict`, :meth:`from_toml`,
    :meth:`example` (``femu init``'s study) or :meth:`demo` (``femu demo``'s). A key the schema
    does not know, a value out of range or a wrong unit suffix raises :class:`femu.StudyError`
    with the message ``femu run`` prints (key and line)."""

    def __init__(self, inner: "_femu.Study"):
        self._inner = inner

    @classmethod
    def load(cls, path: PathLike) -> "Study":
        """Reads and checks a study file; relative paths in it start from its folder."""
        return cls(_femu.Study.load(os.fspath(path)))

    @classmethod
    def from_toml(cls, text: str, base: Optional[PathLike] = None) -> "Study":
        """A study from TOML text; relative paths start from ``base`` (default: the working
        folder)."""
        return cls(_femu.Study.from_toml(text, None if base is None else os.fspath(base)))

    @classmethod
    def from_dict(cls, data: Dict[str, Any], base: Optional[PathLike] = None) -> "Study":
        """A study from a dict of the study file's tables, e.g. ``{"model": {"elements":
        2000}, "identification": {"starts": 3}, "test": [{"kind": "compression"}]}``; written
        as TOML (:attr:`toml`) and checked by the same schema as a file."""
        return cls(_femu.Study.from_dict(data, None if base is None else os.fspath(base)))

    @classmethod
    def example(cls) -> "Study":
        """The commented example study of ``femu init``: the seed's numerical example."""
        return cls(_femu.Study.example())

    @classmethod
    def demo(cls, elements: Optional[int] = None) -> "Study":
        """The study ``femu demo [--elements N]`` runs (4 000 elements by default)."""
        return cls(_femu.Study.demo(elements))

    @property
    def toml(self) -> str:
        """The study as TOML text."""
        return self._inner.toml

    @property
    def path(self) -> Optional[Path]:
        """The study file, when read from one."""
        p = self._inner.path
        return None if p is None else Path(p)

    @property
    def tests(self):
        """The loading tests' names (``contention``, ``compression-anterior``, ...)."""
        return list(self._inner.tests)

    @property
    def identification_test(self) -> str:
        return self._inner.identification_test

    def run(self, out: PathLike, progress: Any = True) -> "RunResult":
        """Runs the whole study into the folder ``out`` as ``femu run STUDY --out OUT`` does
        (model → forward tests → sensitivity → measurement → identification → report.html) and
        returns its typed results. Releases the GIL; Ctrl-C stops it at the next unit of work
        (what finished is kept) and raises ``KeyboardInterrupt``."""
        self._inner.run(os.fspath(out), reporter(progress))
        return RunResult.read(out)

    def step(self, name: str, out: PathLike, progress: Any = True):
        """Runs one step into ``out`` and returns its typed result: ``"model"`` (dict, the
        model folder's summary), ``"forward"`` (``{test: SolveSummary}``), ``"sensitivity"``
        (:class:`~femu.results.SensitivitySummary`), ``"measurement"`` (the virtual
        experiment, a :class:`femu.Field`) or ``"identification"``
        (:class:`~femu.results.IdentificationSummary`, from the study's measurement)."""
        text = self._inner.step(name, os.fspath(out), reporter(progress))
        if name == "model":
            return json.loads(text)
        if name == "forward":
            return {
                test: results.from_dict(results.SolveSummary, results._rename_lambda(v))
                for test, v in json.loads(text).items()
            }
        if name == "sensitivity":
            return results.parse(results.SensitivitySummary, text)
        if name == "measurement":
            return Field.read(json.loads(text))
        return results.parse(results.IdentificationSummary, text)

    def model(self, progress: Any = False):
        """The study's model (mesh and materials, no load), built as ``femu run`` builds it."""
        return Model(_femu.model_of_study(self._inner, reporter(progress)), self._inner)

    def virtual_field(self):
        """The study's measurement as its identification fits it in the first repeat (``femu
        synth``: the test at the reference parameters on the measurement's points plus the
        seeded noise) as a :class:`femu.Field`; a study with a list of measurements gives a
        dict ``{name: Field}``."""
        fields = {
            name: Field(x, y, ux, uy, weights=weights)
            for name, (x, y, ux, uy, weights) in _femu.virtual_field(self._inner)
        }
        if len(fields) == 1:
            return next(iter(fields.values()))
        return fields

    def __repr__(self) -> str:
        return repr(self._inner)


@dataclass
class RunResult:
    """The typed results of a run folder (``femu run``, ``femu demo``, :meth:`Study.run`)."""

    folder: Path
    #: ``steps.json``: every step's status and time.
    record: results.RunRecord
    #: ``summary.json`` (``femu_study::report::RunSummary``), the numbers a user quotes.
    summary: Dict[str, Any] = field(default_factory=dict)
    #: ``model/summary.json`` (a meshed thigh's or a deck's).
    model: Optional[Dict[str, Any]] = None
    #: ``forward/TEST/summary.json`` per test.
    forward: Dict[str, results.SolveSummary] = field(default_factory=dict)
    sensitivity: Optional[results.SensitivitySummary] = None
    #: ``identify/GROUPING/summary.json`` per grouping (``ungrouped``, ``grouped``).
    identification: Dict[str, results.IdentificationSummary] = field(default_factory=dict)
    #: ``measurement/measured.csv``: the field the identification fitted.
    measured: Optional[Any] = None

    @classmethod
    def read(cls, folder: PathLike) -> "RunResult":
        """Reads the typed summaries of a run folder (each checked against its Rust struct)."""
        d = _femu.read_run(os.fspath(folder))
        measured = None
        if "measured" in d:
            measured = Field.read(d["measured"])
        return cls(
            folder=Path(folder),
            record=results.parse(results.RunRecord, d["record"]),
            summary=json.loads(d["summary"]) if "summary" in d else {},
            model=json.loads(d["model"]) if "model" in d else None,
            forward={k: results.parse(results.SolveSummary, v) for k, v in d["forward"].items()},
            sensitivity=(
                results.parse(results.SensitivitySummary, d["sensitivity"])
                if "sensitivity" in d
                else None
            ),
            identification={
                k: results.parse(results.IdentificationSummary, v)
                for k, v in d["identification"].items()
            },
            measured=measured,
        )

    @property
    def report(self) -> Path:
        """The self-contained HTML report."""
        return self.folder / "report.html"


def demo(out: PathLike, elements: Optional[int] = None, progress: Any = True) -> RunResult:
    """``femu demo --out OUT [--elements N]``: the seed's numerical example end to end."""
    return Study.demo(elements).run(out, progress)
