"""femu's residual and exact Jacobian as Python callables: SciPy's ``least_squares`` on them
reaches the optimum of femu's own identification; the Jacobian agrees with finite differences
of the residual; identification from arrays equals ``femu identify --measured``."""

import json
import re

import numpy as np
import pytest

import femu
from _helpers import VOLATILE, differences, plain, run_cli

optimize = pytest.importorskip("scipy.optimize")

#: The seed's example on a 1 500-element thigh, D of ischio, sartorius and gracilis tied, three
#: Latin-hypercube starts: a few seconds per identification.
STUDY = {"model": {"elements": 1500}, "identification": {"starts": 3, "grouped": True}}


@pytest.fixture(scope="module")
def problem():
    study = femu.Study.from_dict(STUDY)
    field = study.virtual_field()  # the seed's noise, sigma = 1.76e-2 mm, seeded
    return study, field


def test_scipy_least_squares_reaches_femus_optimum(problem, tmp_path):
    study, field = problem
    found = femu.identify(study, field, out=tmp_path / "identify", progress=False)
    theta_femu = np.array([p.identified for p in found.parameters])
    sd = np.array([p.relative_sd for p in found.parameters])

    p = femu.LeastSquares(study, field)
    assert p.names == [f.name for f in found.free_parameters]
    # A start away from the reference, inside the bounds (a factor 4 either side).
    start = p.reference * np.array([1.6, 0.6, 1.5, 0.7, 1.4, 0.65, 1.3, 1.5])
    sol = optimize.least_squares(
        p.residual,
        np.log(start),
        jac=p.jacobian,
        bounds=p.bounds,
        method="trf",
        x_scale="jac",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    assert sol.success, sol.message
    theta = np.exp(sol.x)
    # femu's Levenberg–Marquardt stops once the Gauss–Newton model predicts a decrease below
    # 1e-10 of the cost (about 2.6e-7 here): a point that close to the minimum lies within
    # sqrt(2 x 2.6e-7) = 7e-4 standard deviations of it in every parameter. Both optimizers
    # must agree to that (1e-3 sd), and on the cost to 1e-8 (the forward solves' tolerance).
    assert np.all(np.abs(np.log(theta / theta_femu)) < 1e-3 * sd), np.log(theta / theta_femu) / sd
    assert sol.cost == pytest.approx(found.best_cost, rel=1e-8)
    # femu's own optimizer from the same start, through the same callable problem.
    fit = p.levenberg_marquardt(start)
    assert fit.converged
    assert np.all(np.abs(np.log(np.array(fit.theta) / theta_femu)) < 1e-3 * sd)


def test_jacobian_agrees_with_finite_differences_of_the_residual(problem):
    study, field = problem
    p = femu.LeastSquares(study, field)
    phi = p.x0 + 0.1  # away from the optimum: residuals of all sizes
    j = p.jacobian(phi)
    r = p.residual(phi)
    assert j.shape == (len(r), len(p.names))
    # Central differences with a step of 1e-4 in ln θ: truncation O(h²) ~ 1e-8 relative; each
    # forward solve converges to a relative residual of 1e-8, whose noise divided by 2h is
    # ~1e-4 of a column: 2e-3 bounds both with margin.
    h = 1e-4
    for k in range(len(phi)):
        e = np.zeros_like(phi)
        e[k] = h
        fd = (p.residual(phi + e) - p.residual(phi - e)) / (2 * h)
        err = np.linalg.norm(fd - j[:, k]) / np.linalg.norm(j[:, k])
        assert err < 2e-3, (p.names[k], err)


def test_identification_from_arrays_equals_the_command_on_the_same_csv(problem, tmp_path, femu_cli):
    study, field = problem
    toml = tmp_path / "study.toml"
    toml.write_text(study.toml)
    # The field as femu synth writes it (13 significant digits), read back by femu.
    run_cli(femu_cli, "synth", toml, "--out", tmp_path / "synth", "--quiet")
    csv = tmp_path / "synth" / "measured.csv"
    from_csv = femu.Field.read(csv)
    np.testing.assert_allclose(from_csv.ux, field.ux, rtol=1e-12, atol=0)
    run_cli(
        femu_cli, "identify", toml, "--measured", csv, "--out", tmp_path / "cli", "--quiet"
    )
    py = femu.identify(study, from_csv, out=tmp_path / "py", progress=False)
    cli = json.loads((tmp_path / "cli" / "summary.json").read_text())
    # Everything but the name of the data's source (arrays here, the file there).
    source = re.compile(VOLATILE.pattern + r"|^label$|^source$")
    assert differences(plain(py), cli, volatile=source) == []
    assert (tmp_path / "py" / "parameters.csv").read_text() == (
        tmp_path / "cli" / "parameters.csv"
    ).read_text()
