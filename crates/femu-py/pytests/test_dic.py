"""``femu.dic`` on the DIC Challenge 1.0 Sample 5 (a rigid shift of 0.10 px): the same field
and covariance as ``femu dic`` to the last printed digit, from the files and from NumPy arrays;
and the known shift recovered."""

import numpy as np
import pytest

import femu
from _helpers import run_cli, rust_e


@pytest.fixture(scope="module")
def sample5(shared_data):
    d = shared_data / "dic-challenge" / "sample5"
    if not d.is_dir():
        pytest.skip(f"{d} absent: DIC Challenge test skipped")
    return d / "reference.tif", d / "shift_x0.10_y0.10.tif"


def read_csv_rows(path):
    lines = [l for l in path.read_text().splitlines() if l and not l.startswith("#")]
    return lines[0].split(","), [l.split(",") for l in lines[1:]]


@pytest.mark.parametrize("roi", [None, (32, 32, 448, 448)])
def test_field_and_covariance_equal_the_commands(sample5, femu_cli, tmp_path, roi):
    ref, deformed = sample5
    args = ["dic", ref, deformed, "--out", tmp_path / "cli", "--no-figures", "--quiet"]
    if roi:
        x, y, w, h = roi
        args += ["--roi", f"{x},{y},{w}x{h}"]
    run_cli(femu_cli, *args)
    r = femu.dic(ref, deformed, out=tmp_path / "py", figures=False, roi=roi)

    header, rows = read_csv_rows(tmp_path / "cli" / "field.csv")
    assert header == ["x", "y", "ux", "uy", "sx", "sy", "w"]
    assert len(rows) == len(r.field["x"])
    for k, row in enumerate(rows):
        # field.csv's formats (femu_dic::output::write_field_csv).
        got = [rust_e(r.field[c][k], 12) for c in ("x", "y", "ux", "uy")]
        got += [rust_e(r.field[c][k], 6) for c in ("sx", "sy")]
        assert row[:6] == got, k
        assert float(row[6]) == r.field["w"][k]

    # covariance.mtx: the lower triangle, 1-based, each value in its shortest exact form ({:e}):
    # it reads back to the same float.
    c = r.covariance().tocoo()
    mine = {(i + 1, j + 1): v for i, j, v in zip(c.row, c.col, c.data) if i >= j}
    lines = (tmp_path / "cli" / "covariance.mtx").read_text().splitlines()
    entries = [l.split() for l in lines if not l.startswith("%")][1:]
    assert len(entries) == len(mine)
    for i, j, v in entries:
        assert float(v) == mine[(int(i), int(j))]
    # The Python call wrote the same files.
    for name in ("field.csv", "nodes.csv", "covariance.mtx", "elements.csv"):
        assert (tmp_path / "py" / name).read_text() == (tmp_path / "cli" / name).read_text()


def test_arrays_give_the_files_result_and_the_known_shift(sample5):
    ref, deformed = sample5
    f, size = femu.read_image(ref)
    g, _ = femu.read_image(deformed)
    assert f.shape == (512, 512) and size is None
    from_files = femu.dic(ref, deformed, figures=False)
    from_arrays = femu.dic(f, g, figures=False)
    for c in ("x", "y", "ux", "uy", "sx", "sy", "w"):
        np.testing.assert_array_equal(from_arrays.field[c], from_files.field[c])
    # The rigid shift of +0.10 px: the bias of femu-dic's own Sample 5 test (0.01 px).
    trusted = from_arrays.nodes["w"] == 1
    mean = from_arrays.nodes["u_px"][trusted].mean(axis=0)
    assert np.all(np.abs(mean - 0.10) <= 0.01), mean
    # The covariance's diagonal is the square of the nodal standard deviations.
    diag = from_arrays.covariance().diagonal()
    np.testing.assert_allclose(np.sqrt(diag[0::2]), from_arrays.nodes["sd_px"][:, 0], rtol=1e-12)
    assert from_arrays.report.result.converged


def test_uint16_images_read_as_16_bit_files(sample5):
    ref, deformed = sample5
    f, _ = femu.read_image(ref)
    g, _ = femu.read_image(deformed)
    eight = femu.dic(f, g, figures=False, element=16, regularization="off")
    sixteen = femu.dic(
        (f * 257).astype(np.uint16), (g * 257).astype(np.uint16), figures=False, element=16,
        regularization="off",
    )
    np.testing.assert_allclose(sixteen.field["ux"], eight.field["ux"], rtol=0, atol=1e-12)
