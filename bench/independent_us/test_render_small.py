"""Small checks of render_pymust.py (pytest; < 1 min): pymust's speckle follows a known rigid
shift of the scatterers, a --small realization writes consistent files, the Hann apodization
widens the speckle; psf_phase.py's point-spread function and the shear shift it predicts, and
shear_correction.py's differences.

    pip install pymust==0.1.9 scipy pillow pytest
    pytest bench/independent_us/test_render_small.py
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymust", reason="pymust is not installed (pip install pymust==0.1.9)")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import render_pymust as rp  # noqa: E402


def test_rigid_shift_moves_the_speckle_by_the_shift():
    """A 64 x 64 px frame of a few hundred random scatterers, then the same scatterers moved
    0.5 mm laterally and 0.3 mm axially (5 and 3 px at 0.1 mm): the phase correlation of the
    two B-mode frames finds that shift."""
    s = rp.small_settings()
    ren = rp.Renderer(s, 64, 64, z0_mm=8.0)  # the window 8-14.4 mm deep: past the near field
    rng = np.random.default_rng(7)
    n = 400
    # Scatterers over the window and a margin wider than the shift, so that the speckle that
    # enters the window on one side was there before the shift too.
    q = np.column_stack([rng.uniform(-4.4, 4.4, n), rng.uniform(6.5, 16.0, n)])
    rc = rng.standard_normal(n)
    shift = np.array([0.5, 0.3])  # mm: lateral, depth
    frames = []
    for qq in (q, q + shift):
        v = ren.in_view(qq)
        env = np.abs(ren.iq_image(qq[v], rc[v]))
        frames.append(20 * np.log10(env / env.max() + 1e-6))
    dx, dy = rp.phase_correlation(frames[0], frames[1])
    # 0.5 px: the brief's tolerance; speckle of a rigidly moved scatterer field moves with it
    # up to the PSF's small change with position (the plane wave and the receive aperture
    # are nearly shift-invariant over 0.5 mm).
    assert abs(dx - 5.0) < 0.5, (dx, dy)
    assert abs(dy - 3.0) < 0.5, (dx, dy)


def test_small_run_writes_consistent_files(tmp_path):
    pytest.importorskip(
        "femu", reason="femu's Python package is not installed (.ci/python builds it)")
    out = tmp_path / "small"
    r = subprocess.run(
        [sys.executable, str(HERE / "render_pymust.py"), "--small", "--seed", "3",
         "--out", str(out), "--quiet"],
        capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "manifest.json").read_text())
    w, h = m["image_px"]
    assert (w, h) == (64, 64)
    assert len(m["frames"]) == len(m["loads_n_per_mm"]) == len(m["truth"]) + 1 == 3
    assert m["loads_n_per_mm"][0] == 0.0 and m["loads_n_per_mm"][-1] == pytest.approx(0.1)
    from PIL import Image

    for name in m["frames"]:
        img = Image.open(out / name)
        assert img.mode == "L" and img.size == (w, h)
        a = np.asarray(img)
        assert a.std() > 5, f"{name} is blank"
    meas = m["measurement"]
    assert meas["units"] == "px" and meas["pixel_size_mm"] == pytest.approx(0.1)
    x_axis, y_axis = np.array(meas["x_axis"]), np.array(meas["y_axis"])
    assert abs(x_axis @ y_axis) < 1e-12 and abs(np.linalg.norm(x_axis) - 1) < 1e-12
    pts = None
    for k, name in enumerate(m["truth"], start=1):
        t = np.genfromtxt(out / name, delimiter=",", names=True)
        assert t.dtype.names == ("x_px", "y_px", "ux_px", "uy_px")
        assert len(t) > 10
        assert (t["x_px"] >= 0).all() and (t["x_px"] < w).all()
        assert (t["y_px"] >= 0).all() and (t["y_px"] < h).all()
        assert (np.mod(t["x_px"], 8) == 0).all() and (np.mod(t["y_px"], 8) == 0).all()
        p = np.column_stack([t["x_px"], t["y_px"]])
        assert pts is None or np.array_equal(p, pts)
        pts = p
    # The plate pushes the tissue away from the probe: the last step moves it down the image.
    assert np.mean(t["uy_px"]) > 0
    assert m["timings_s"]["total_wall"] < 60


def test_hann_apodization_weighs_the_aperture_and_widens_the_speckle():
    """--rx-apodization hann: each DAS entry is multiplied by cos^2(pi dx f-number / depth) of its
    element's lateral distance dx (zero at the f-number aperture's edge, one at its centre), the
    gain is each pixel's sum of squared element weights (the element count without
    apodization), and the lateral speckle grows wider (a narrower effective aperture)."""
    s = rp.small_settings()
    h = rp.Settings(**{**rp.asdict(s), "rx_apodization": "hann"})
    rng = np.random.default_rng(11)
    q = np.column_stack([rng.uniform(-4.4, 4.4, 600), rng.uniform(6.5, 16.0, 600)])
    rc = rng.standard_normal(600)
    widths = []
    for settings in (s, h):
        ren = rp.Renderer(settings, 64, 64, z0_mm=8.0)
        v = ren.in_view(q)
        env = np.abs(ren.iq_image(q[v], rc[v]))
        b = env - env.mean()
        # Lateral lag at which the envelope's autocorrelation falls below one half.
        ac = [(b[:, :64 - k] * b[:, k:]).mean() / (b * b).mean() for k in range(10)]
        widths.append(next(k for k, a in enumerate(ac) if a < 0.5))
        if settings is h:
            m, gain = ren._das[0][1], ren.aperture
    assert widths[1] > widths[0], widths
    # The weights against a direct computation at a few pixels, and the gain.
    plain = rp.Renderer(s, 64, 64, z0_mm=8.0)
    plain.iq_image(q[:5], rc[:5])
    m0 = plain._das[0][1].tocsr()
    m = m.tocsr()
    samples = m.shape[1] // s.n_elements
    xe = (np.arange(s.n_elements) - 0.5 * (s.n_elements - 1)) * s.pitch_mm * 1e-3
    x, z = plain.X.flatten(order="F"), plain.Z.flatten(order="F")
    for p in (0, 1000, 2047, 4095):
        a, b = m0.getrow(p), m.getrow(p)
        assert np.array_equal(a.indices, b.indices)
        e = a.indices // samples
        w = np.cos(np.pi * np.abs(xe[e] - x[p]) * s.rx_fnumber / z[p]) ** 2
        assert np.allclose(b.data, a.data * w, rtol=1e-12, atol=0)
        n = np.unique(e)
        wn = np.cos(np.pi * np.abs(xe[n] - x[p]) * s.rx_fnumber / z[p]) ** 2
        assert np.isclose(gain.flatten(order="F")[p], np.sum(wn**2), rtol=1e-12)


def test_psf_phase_of_a_point_and_the_shear_shift_it_predicts():
    """psf_phase.py on one point 10 mm deep (Hann apodization): the axial carrier is close to
    2k (73.4 rad/mm at 9 MHz; pymust's echoes are centred a little lower), the lateral phase
    curves with the sign and about the size of the focal plane's -k/(2z) (-1.84 rad/mm^2), and
    the shift the PSF's own cross-correlation predicts under a shear of 0.05 is within 0.4 px
    of the closed form with the fitted curvature and width (measured at 5-38 mm: within 0.4 px;
    the README's table)."""
    import psf_phase as pp

    s = rp.Settings(rx_apodization="hann")
    x, z, img = pp.point_psf(s, 10.0)
    i0 = np.unravel_index(np.argmax(np.abs(img)), img.shape)[0]
    alpha, sigma, _ = pp.lobe_fit(x, img[i0, :])
    k = 2 * np.pi * s.fc_mhz * 1e6 / rp.SOUND_SPEED / 1e3
    k2 = pp.carrier(z, img)
    assert 0.9 * 2 * k < k2 < 1.02 * 2 * k, k2
    assert -k / (2 * 10.0) * 1.2 < alpha < -k / (2 * 10.0) * 0.6, alpha
    assert 0.3 < sigma < 0.5, sigma
    closed = pp.closed_form_shift(k2, alpha, sigma, 0.05) * 10
    shift = pp.correlation_shift(x, z, img, 0.05, k2) * 10
    assert shift > 1.0 and abs(shift - closed) < 0.4, (shift, closed)


def test_shear_by_differences_along_the_rows():
    """shear_correction.shear_of: exact on a quadratic field along unevenly spaced rows, with
    one-sided differences beside a missing point and at the ends."""
    import shear_correction as sc

    x = np.array([0.0, 1, 2, 3, 5, 0, 1, 2])
    y = np.array([0.0, 0, 0, 0, 0, 1, 1, 1])
    uy = 0.05 * x + 0.002 * x**2
    g = sc.shear_of(x, y, uy)
    central = 0.05 + 0.004 * x
    # Central (interior points of row 0, x = 1, 2, 3; row 1, x = 1): exact for a quadratic.
    for i in (1, 2, 3, 6):
        assert abs(g[i] - central[i]) < 1e-12, (i, g[i])
    # One-sided at the ends: the slope of the chord.
    assert abs(g[0] - (uy[1] - uy[0])) < 1e-12
    assert abs(g[4] - (uy[4] - uy[3]) / 2) < 1e-12
    assert abs(g[7] - (uy[7] - uy[6])) < 1e-12


def test_scale_the_true_field_supports(tmp_path):
    """speckle_shift_campaign.true_scale: a composed field whose lateral error is 0.7 c(z) g of
    a true field with a shear varying over the image gives back 0.7 (the truth on a 4 px grid,
    interpolated; the shear linear in x, so central differences are exact)."""
    import shear_correction as sc
    import speckle_shift_campaign as ssc

    xs, ys = np.arange(0, 400, 4.0), np.arange(0, 400, 4.0)
    X, Y = np.meshgrid(xs, ys)
    ux = 2.0 + 0.01 * X
    uy = 1e-4 * X**2 + 0.002 * X * Y / 10  # px: shear duy/dx = 2e-4 x + 2e-4 y
    truth = tmp_path / "truth.csv"
    np.savetxt(truth, np.c_[X.ravel(), Y.ravel(), ux.ravel(), uy.ravel()], delimiter=",",
               header="x_px,y_px,ux_px,uy_px", comments="")
    px, py = np.meshgrid(np.arange(20, 380, 16.0), np.arange(20, 380, 16.0))
    px, py = px.ravel(), py.ravel()
    g = 2e-4 * px + 2e-4 * py
    c = sc.lens_shift_per_shear(9, 0.907, py / 10 + 0.05)
    field = tmp_path / "field.csv"
    with open(field, "w") as fh:
        fh.write("# units: mm\nx,y,ux,uy,sx,sy,w\n")
        for x, y, gi, ci in zip(px, py, g, c):
            u = (2.0 + 0.01 * x) / 10 + 0.7 * ci * gi
            v = (1e-4 * x**2 + 0.002 * x * y / 10) / 10
            fh.write(f"{x / 10},{y / 10},{u},{v},0.01,0.01,1\n")
    assert abs(ssc.true_scale(str(field), str(truth), 9, 0.907) - 0.7) < 1e-3
