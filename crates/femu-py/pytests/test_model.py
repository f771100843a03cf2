"""Models and forward solves from Python: a loading test solved for given parameters equals
``femu forward`` to the last bit; the exact sensitivities (nodes x 2 x parameters) agree with
central finite differences of the solves; a label image handed over as a NumPy array meshes as
the same image read from a PNG file; parameters are checked by name and range."""

import csv

import numpy as np
import pytest

import femu
from _helpers import run_cli

#: A coarse built-in thigh: a solve takes about a second at the test profile.
ELEMENTS = 700


@pytest.fixture(scope="module")
def thigh():
    return femu.Model.thigh(elements=ELEMENTS)


def test_a_solve_equals_femu_forward_bit_for_bit(thigh, femu_cli, tmp_path):
    run_cli(
        femu_cli, "forward", "--elements", ELEMENTS, "--tests", "compression",
        "--out", tmp_path, "--quiet",
    )
    (folder,) = [d for d in tmp_path.iterdir() if d.is_dir()]  # compression-anterior
    with open(folder / "displacements.csv") as f:
        rows = list(csv.DictReader(f))
    s = thigh.solve("compression")
    assert s.u.shape == (len(thigh.nodes), 2) == (len(rows), 2)
    # displacements.csv holds the shortest decimals that read back to the same doubles.
    x = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    u = np.array([[float(r["ux"]), float(r["uy"])] for r in rows])
    np.testing.assert_array_equal(thigh.nodes, x)
    np.testing.assert_array_equal(s.u, u)
    assert s.report.lambda_ == 1.0
    assert s.stress.shape == (len(thigh.elements), 4)
    assert s.log_strain.shape == (len(thigh.elements), 4)
    assert np.all(s.volume_ratio > 0)
    # The plate's reaction balances the applied 0.1 N/mm: the femur's reactions sum to it.
    assert s.bodies and abs(abs(s.reactions[:, 1].sum()) - 0.1) < 1e-6


def test_exact_sensitivities_agree_with_finite_differences(thigh):
    sens = thigh.sensitivities("compression")
    n = len(thigh.nodes)
    assert sens.du.shape == (n, 2, len(sens.names))
    assert sens.names == list(thigh.parameters)
    np.testing.assert_array_equal(sens.u, thigh.solve("compression").u)
    for name in ("C10_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"):
        k = sens.names.index(name)
        theta = sens.values[k]
        # Central differences with a relative step of 1e-4: truncation ~1e-8 relative; each
        # solve converges to a relative residual of 1e-8, whose noise over the step is ~1e-4
        # of the column; 2e-3 bounds both with margin (as femu-mech's own check).
        h = 1e-4 * theta
        up = thigh.solve("compression", {name: theta + h}).u
        down = thigh.solve("compression", {name: theta - h}).u
        fd = (up - down) / (2 * h)
        err = np.linalg.norm(fd - sens.du[:, :, k]) / np.linalg.norm(sens.du[:, :, k])
        assert err < 2e-3, (name, err)
    # The seed's Eq. 3 index from the arrays: ||theta dU/dtheta|| / ||U||.
    idx = np.linalg.norm(sens.du * sens.values, axis=(0, 1)) / np.linalg.norm(sens.u)
    np.testing.assert_allclose(sens.index, idx, rtol=1e-10)


def test_parameters_are_checked_by_name_and_range(thigh):
    with pytest.raises(femu.InputError, match="unknown parameter 'C10_FATT'.*C10_FAT"):
        thigh.solve("compression", {"C10_FATT": 1e-3})
    with pytest.raises(femu.InputError, match="parameter C10_FAT = -1: outside the range"):
        thigh.solve("compression", {"C10_FAT": -1.0})


def synthetic_slice():
    """A round thigh: fat ring (1), muscle (2), bone (7) in background (0); 1 mm pixels."""
    yy, xx = np.mgrid[0:160, 0:180]
    r = np.hypot(xx - 90.0, yy - 80.0)
    labels = np.zeros((160, 180), dtype=np.uint8)
    labels[r < 70] = 1
    labels[r < 60] = 2
    labels[r < 12] = 7
    return labels


def test_a_label_array_meshes_as_the_same_png(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    labels = synthetic_slice()
    Image.fromarray(labels).save(tmp_path / "slice.png")
    entry = {"map": "1=fat,2=quadriceps", "bone": [7], "background": [0], "pixel_size_mm": 1.0}
    from_file = femu.Study.from_dict(
        {"model": {"size_mm": 4.0}, "labels": dict(entry, image="slice.png")}, base=tmp_path
    ).model()
    from_array = femu.Model.from_labels(labels, size_mm=4.0, **entry)
    np.testing.assert_array_equal(from_array.nodes, from_file.nodes)
    np.testing.assert_array_equal(from_array.elements, from_file.elements)
    assert from_array.region_names == from_file.region_names == ["FAT", "QUADRICEPS"]
    assert from_array.parameters == from_file.parameters
    s = from_array.solve("contention")
    assert s.report.lambda_ == 1.0 and np.abs(s.u).max() > 0


def test_bad_label_arrays_are_refused():
    entry = {"map": "1=fat,2=quadriceps", "pixel_size_mm": 1.0}
    with pytest.raises(femu.InputError, match="expected an integer array"):
        femu.Model.from_labels(synthetic_slice().astype(float), **entry)
    with pytest.raises(femu.InputError, match="two-dimensional"):
        femu.Model.from_labels(np.zeros((2, 3, 4), dtype=np.uint8), **entry)
    bad = synthetic_slice().astype(np.int32)
    bad[5, 9] = -3
    with pytest.raises(femu.InputError, match=r"pixel \(row 5, column 9\) holds -3"):
        femu.Model.from_labels(bad, **entry)


def test_meshio_and_pyvista_conversions(thigh):
    s = thigh.solve("contention")
    try:
        import meshio
    except ImportError:
        meshio = None
        print("meshio not installed: conversion to meshio not checked")
    if meshio is not None:
        m = s.to_meshio()
        assert len(m.points) == len(thigh.nodes)
        assert sum(len(c.data) for c in m.cells) == len(thigh.elements)
        np.testing.assert_array_equal(m.point_data["u"][:, :2], s.u)
    try:
        import pyvista
    except ImportError:
        pyvista = None
        print("pyvista not installed: conversion to PyVista not checked")
    if pyvista is not None:
        g = s.to_pyvista()
        assert g.n_points == len(thigh.nodes) and g.n_cells == len(thigh.elements)
        np.testing.assert_array_equal(np.asarray(g.point_data["u"])[:, :2], s.u)
