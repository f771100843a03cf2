"""Bad inputs raise the documented exceptions (README, ``femu.FemuError`` and its subclasses)
with the message the ``femu`` command prints after ``error:`` for the same input (the file,
line, key or element at fault)."""

import numpy as np
import pytest

import femu
from _helpers import run_cli


def cli_error(cli, *args) -> str:
    """The message ``femu ARGS`` prints after ``error: `` (it must fail), to the end (a TOML
    error quotes its line below)."""
    p = run_cli(cli, *args, check=False)
    assert p.returncode != 0, p.stdout
    at = p.stderr.find("error: ")
    assert at >= 0, p.stderr
    return p.stderr[at + len("error: "):].rstrip("\n")


def test_the_exception_tree():
    for cls in (
        femu.StudyError, femu.InputError, femu.SolveError, femu.DicError,
        femu.IdentificationError,
    ):
        assert issubclass(cls, femu.FemuError)
    assert issubclass(femu.FemuError, Exception)


BAD_STUDIES = {
    # An unknown key (a misspelt table entry), named with its line.
    "unknown-key": "[model]\nelements = 2000\nelemnts = 3\n",
    # A value out of range.
    "out-of-range": "[model]\nelements = 12\n",
    # A wrong unit suffix is an unknown key.
    "wrong-unit": "[materials.fat]\nc10_mpa_x = 1.0\n",
    # A type error.
    "type": "[identification]\nstarts = \"three\"\n",
}


@pytest.mark.parametrize("case", sorted(BAD_STUDIES))
def test_a_bad_study_file_raises_study_error_with_the_commands_message(case, tmp_path, femu_cli):
    path = tmp_path / "study.toml"
    path.write_text(BAD_STUDIES[case])
    expected = cli_error(femu_cli, "run", path, "--out", tmp_path / "out", "--quiet")
    with pytest.raises(femu.StudyError) as e:
        femu.Study.load(path)
    assert str(e.value).rstrip("\n") == expected
    # The same text as TOML or the same tables as a dict: the same schema, the same complaint
    # (without the file's name).
    with pytest.raises(femu.StudyError) as e:
        femu.Study.from_toml(BAD_STUDIES[case])
    assert "line" in str(e.value) or case == "out-of-range"


def test_a_dict_with_a_misspelt_key():
    with pytest.raises(femu.StudyError, match="elemnts"):
        femu.Study.from_dict({"model": {"elemnts": 2000}})
    with pytest.raises(femu.StudyError, match="model.elements: None is not a value"):
        femu.Study.from_dict({"model": {"elements": None}})
    with pytest.raises(femu.StudyError, match="a object cannot be written|cannot be written"):
        femu.Study.from_dict({"model": {"elements": object()}})


def test_a_missing_study_file(tmp_path, femu_cli):
    path = tmp_path / "absent.toml"
    expected = cli_error(femu_cli, "run", path, "--out", tmp_path / "out", "--quiet")
    with pytest.raises(femu.FemuError) as e:
        femu.Study.load(path)
    assert str(e.value) == expected
    assert "absent.toml" in str(e.value)


def test_a_bad_measured_field_names_its_line(tmp_path, femu_cli):
    csv = tmp_path / "measured.csv"
    csv.write_text("x,y,ux,uy\n1.0,2.0,0.1,0.2\n1.5,2.0,zero,0.2\n")
    with pytest.raises(femu.InputError) as e:
        femu.Field.read(csv)
    assert f"{csv}:3: column ux: 'zero' is not a number" in str(e.value), str(e.value)
    # `femu identify --measured` reads it with the same reader: the same complaint inside.
    study = tmp_path / "study.toml"
    study.write_text("[model]\nelements = 700\n")
    expected = cli_error(femu_cli, "identify", study, "--measured", csv, "--out", tmp_path / "o")
    assert str(e.value) in expected


def test_bad_arrays_of_a_field():
    study = femu.Study.from_dict({"model": {"elements": 700}})
    x = np.zeros(3)
    with pytest.raises(femu.InputError, match="uy has 2 values, x has 3"):
        femu.identify(study, femu.Field(x, x, x, x[:2]), progress=False)
    with pytest.raises(femu.InputError, match=r"ux\[1\] is not finite"):
        femu.identify(study, femu.Field(x, x, [0, np.nan, 0], x), progress=False)
    with pytest.raises(femu.InputError, match="point 2: sx, sy must be positive"):
        femu.identify(study, femu.Field(x, x, x, x, sx=[1, 1, 0], sy=[1, 1, 1]), progress=False)
    with pytest.raises(femu.InputError, match="phi has 1 values for"):
        femu.LeastSquares(study).residual([0.0])


def test_bad_dic_inputs(tmp_path):
    rng = np.random.default_rng(7)
    f = rng.uniform(0, 255, (64, 64))
    with pytest.raises(femu.DicError, match="region of interest: 40,40,64x64 reaches column 104"):
        femu.dic(f, f, roi=(40, 40, 64, 64), figures=False)
    with pytest.raises(femu.InputError, match="min_zncc 1.5: must lie in"):
        femu.dic(f, f, min_zncc=1.5)
    with pytest.raises(femu.InputError, match="expected a path or a two-dimensional array"):
        femu.dic(f[0], f)
    with pytest.raises(femu.InputError, match="brightness 'local'"):
        femu.dic(f, f, brightness="local")
    with pytest.raises(femu.DicError, match="absent.png"):
        femu.dic(tmp_path / "absent.png", f)


def test_an_unknown_step_or_test():
    study = femu.Study.from_dict({"model": {"elements": 700}})
    with pytest.raises(femu.InputError, match="unknown step 'solve'"):
        study.step("solve", "unused", progress=False)
    with pytest.raises(femu.StudyError, match="kind"):
        study.model().solve({"kind": "shearing"})


def test_a_forward_solve_that_cannot_converge_raises_solve_error():
    """The seed's indentation force (3 N/mm, 30 times femu's default) on the smallest thigh
    passes the model's limit point: the Newton solver gives up and says where, as `femu
    forward` does; from Python that is a ``femu.SolveError`` (not a crash, not NaN arrays)."""
    model = femu.Model.thigh(elements=700)
    with pytest.raises(femu.SolveError) as e:
        model.solve({"kind": "indentation", "force_n_per_mm": 3.0})
    message = str(e.value)
    # The solver's diagnostics (the increment it stopped at), not an empty or generic text.
    assert any(w in message.lower() for w in ("increment", "newton", "converge", "limit")), message
