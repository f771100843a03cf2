#!/usr/bin/env python3
"""The lateral phase of pymust's point-spread function, and the lateral speckle shift it predicts
under a shear.

A delay-and-sum image of a point at depth z, focused on receive at every pixel, carries the
quadratic phase of a lens's focal plane: seen from a pixel dx to the side, the point's echo
arrives on element e later by ((xe - x - dx)^2 - (xe - x)^2) / (2 z c), whose part common to
the whole aperture is dx^2 / (2 z c). The IQ point-spread function is then, near its peak,

    h(dx, dz) ~ A(dx, dz) exp(i k2 dz + i alpha dx^2),   alpha = -k / (2 z)

(k = 2 pi fc / c the one-way wavenumber, k2 = 2 k; a plane-wave transmit adds no lateral
phase). Under a shear duy/dx = g, the scatterers' axial shifts grow across the beam: the PSF
seen by the speckle becomes h(dx, dz + g dx), and the envelope's speckle moves laterally by the
argmax of |sum_d conj(h(d)) h(d_x + s, d_z + g (d_x + s))|, for a Gaussian lateral amplitude
of standard deviation sigma

    shift = beta alpha / (2 (alpha^2 + 1 / (4 sigma^4))),   beta = -k2 g

(speckle_shear.py, checked with femu dic on Gaussian speckle). This script renders single
points with render_pymust.py's `Renderer` (its settings, `--rx-apodization`) on a fine grid
(100 px/mm, 8 x 1.2 mm around each point), and prints per depth:

- the axial phase slope (rad/mm; k2 is 73.4 at 9 MHz) and the lateral phase curvature alpha
  (rad/mm^2) fitted on the peak row over the main lobe (|h| above a quarter of its peak),
  beside -k / (2 z);
- sigma of a Gaussian fitted to the peak row's |h| over the same lobe;
- the speckle's lateral shift under g = 0.05 (px of 0.1 mm), from the closed form with the
  fitted alpha and sigma and from the argmax of the measured PSF's own cross-correlation;
- when `--field` names a `femu dic` field.csv of homogeneous speckle under that shear
  (shift_variance.py --motions SH: true lateral displacement zero), its mean lateral
  displacement in a 2 mm band around the depth, columns 60-340.

    python bench/independent_us/psf_phase.py --rx-apodization hann --field /tmp/svh/dic_SH/field.csv
"""
import argparse
import json
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render_pymust as rp  # noqa: E402
import shift_variance as sv  # noqa: E402

FINE_PX_PER_MM = 100.0
HALF_WIDTH_MM = 4.0
HALF_DEPTH_MM = 0.6
SHEAR = 0.05


def point_psf(s: rp.Settings, z_mm: float):
    """pymust's IQ image of a unit point at (0, z_mm): (x, z) axes (mm, relative to the point)
    and the complex image (rows: depth)."""
    fine = rp.Settings(**{**s.__dict__, "px_per_mm": FINE_PX_PER_MM})
    w = int(round(2 * HALF_WIDTH_MM * FINE_PX_PER_MM))
    h = int(round(2 * HALF_DEPTH_MM * FINE_PX_PER_MM))
    ren = rp.Renderer(fine, w, h, z0_mm=z_mm - HALF_DEPTH_MM)
    # The silent corner scatterers where a whole frame's are (Renderer.rf): simus sizes its RF
    # (and, with a frequency step above 1, its period) from the scatterers' extent, and a
    # small window's corners left the deepest points' echoes aliased away.
    ren.x_lim = 0.5 * s.width_mm + s.margin_mm
    ren.z_max = s.depth_mm + s.margin_mm
    img = ren.iq_image(np.array([[0.0, z_mm]]), np.array([1.0]))
    x = ren.X[0, :] * 1e3
    z = ren.Z[:, 0] * 1e3 - z_mm
    return x, z, img


def lobe_fit(x, row):
    """Over the main lobe (|h| above a quarter of its peak, contiguous around the peak): the
    lateral phase's quadratic coefficient (rad/mm^2, weighted by |h|^2) and the sigma of a
    Gaussian fitted to log |h|."""
    a = np.abs(row)
    i0 = int(np.argmax(a))
    lo = i0
    while lo > 0 and a[lo - 1] >= 0.25 * a[i0]:
        lo -= 1
    hi = i0
    while hi < len(a) - 1 and a[hi + 1] >= 0.25 * a[i0]:
        hi += 1
    sl = slice(lo, hi + 1)
    xs = x[sl] - x[i0]
    phase = np.unwrap(np.angle(row[sl]))
    wts = a[sl]
    alpha = np.polyfit(xs, phase, 2, w=wts)[0]
    c2 = np.polyfit(xs, np.log(a[sl]), 2, w=wts)[0]
    sigma = np.sqrt(-1.0 / (2.0 * c2)) if c2 < 0 else np.nan
    return alpha, sigma, x[i0]


def closed_form_shift(k2, alpha, sigma, g):
    """The speckle's lateral shift (mm) under the shear g for a PSF with the axial carrier k2
    (rad/mm), the lateral phase curvature alpha (rad/mm^2) and a Gaussian lateral amplitude of
    standard deviation sigma (mm): beta alpha / (2 (alpha^2 + 1 / (4 sigma^4))), beta = -k2 g
    (the module docstring; speckle_shear.py checks it with femu dic)."""
    beta = -k2 * g
    return beta * alpha / (2 * (alpha**2 + 1 / (4 * sigma**4)))


def sheared(z, img, g, x, k2):
    """h(dx, dz + g dx): each column's complex profile read at depth dz + g dx (linear
    interpolation of the baseband: the carrier k2 dz, `carrier`'s, is taken out and put back)."""
    out = np.zeros_like(img)
    base = img * np.exp(-1j * k2 * z)[:, None]
    for j in range(img.shape[1]):
        zz = z + g * x[j]
        re = np.interp(zz, z, base[:, j].real, left=0, right=0)
        im = np.interp(zz, z, base[:, j].imag, left=0, right=0)
        out[:, j] = (re + 1j * im) * np.exp(1j * k2 * zz)
    return out


def carrier(z, img):
    """The axial phase slope (rad/mm) on the column through the peak, over the main lobe."""
    j = np.unravel_index(np.argmax(np.abs(img)), img.shape)[1]
    col = img[:, j]
    a = np.abs(col)
    m = a >= 0.25 * a.max()
    return np.polyfit(z[m], np.unwrap(np.angle(col[m])), 1, w=a[m])[0]


def correlation_shift(x, z, img, g, k2):
    """The lateral shift (mm) at which the PSF's cross-correlation with its sheared self peaks
    (axial shift free), with a parabolic refinement on the lateral samples; k2 the PSF's
    carrier (`carrier`)."""
    h2 = sheared(z, img, g, x, k2)
    f1 = np.fft.fft2(img)
    f2 = np.fft.fft2(h2)
    r = np.abs(np.fft.ifft2(np.conj(f1) * f2))
    i, j = np.unravel_index(np.argmax(r), r.shape)
    n = r.shape[1]
    jm, jp = (j - 1) % n, (j + 1) % n
    den = r[i, jm] - 2 * r[i, j] + r[i, jp]
    frac = 0.5 * (r[i, jm] - r[i, jp]) / den if den != 0 else 0.0
    jj = j if j <= n // 2 else j - n
    return (jj + frac) / FINE_PX_PER_MM


def measured_bias(path, depth_mm):
    """Mean lateral displacement (px) of a femu dic field.csv (mm) in the 2 mm band around
    depth_mm, columns 60-340 px, trusted points."""
    f = sv.load_csv(path)
    m = (f["w"] > 0) & (f["x"] > 6.0) & (f["x"] < 34.0) & (np.abs(f["y"] - depth_mm) <= 1.0)
    return (np.mean(f["ux"][m]) * 10.0, int(m.sum())) if m.any() else (np.nan, 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rx-apodization", choices=["none", "hann"], default="hann")
    ap.add_argument("--depths", default="3,5,8,11,15,20,25,30,35")
    ap.add_argument("--field", help="femu dic field.csv of shift_variance.py's SH motion")
    ap.add_argument("--json", help="write the rows here")
    a = ap.parse_args()
    s = rp.Settings(rx_apodization=a.rx_apodization)
    k = 2 * np.pi * s.fc_mhz * 1e6 / rp.SOUND_SPEED / 1e3  # rad/mm
    print(f"pymust {rp.pymust_version()}, {s.fc_mhz} MHz, receive f-number {s.rx_fnumber}, "
          f"apodization {s.rx_apodization}; k = {k:.2f} rad/mm, shear g = {SHEAR}")
    print("depth  k2 fit  alpha fit  -k/(2z)  sigma   shift (px): closed form  PSF correlation"
          + ("  measured (points)" if a.field else ""))
    rows = []
    for z in [float(v) for v in a.depths.split(",")]:
        t = time.time()
        x, zz, img = point_psf(s, z)
        i0 = np.unravel_index(np.argmax(np.abs(img)), img.shape)[0]
        alpha, sigma, _ = lobe_fit(x, img[i0, :])
        k2 = carrier(zz, img)
        closed = closed_form_shift(k2, alpha, sigma, SHEAR) * 10.0
        corr = correlation_shift(x, zz, img, SHEAR, k2) * 10.0
        row = {"depth_mm": z, "k2_fit": k2, "alpha_fit": alpha, "alpha_lens": -k / (2 * z),
               "sigma_mm": sigma, "shift_closed_px": closed, "shift_psf_px": corr}
        line = (f"{z:5.1f}  {k2:6.1f}  {alpha:9.2f}  {-k / (2 * z):7.2f}  {sigma:5.3f}   "
                f"{closed:+10.2f}  {corr:+15.2f}")
        if a.field:
            b, n = measured_bias(a.field, z)
            row.update(measured_px=b, measured_points=n)
            line += f"  {b:+8.2f} ({n})"
        rows.append(row)
        print(line + f"   [{time.time() - t:.0f} s]", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"pymust": rp.pymust_version(), "settings": s.__dict__, "shear": SHEAR,
                       "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
