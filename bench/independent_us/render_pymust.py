#!/usr/bin/env python3
"""B-mode frames of femu's default compression experiment rendered by pymust.

pymust (the Python port of the MUST toolbox, Garcia 2022) simulates the RF signals of a linear
array (``simus``), they are demodulated (``rf2iq``) and beamformed by delay-and-sum onto the
pixel grid (``dasmtx``); the envelope is log-compressed to 8-bit grey. The tissue is femu's
built-in thigh (Table 1 materials) compressed by a rigid plate on the anterior skin; the FE
displacement of each load step comes from femu's Python package (``femu.Model.thigh().solve``)
on a finer mesh than femu identifies with. Scatterers are drawn at random (seeded) in the
reference configuration of the probe window and moved to each load step by the FE
displacement (bilinear shape functions of the element holding each one).

    python render_pymust.py --seed 1 --out out/indep/seed_01
    python render_pymust.py --small --out /tmp/small      # a 64 x 64 px run in well under a minute

Writes into ``--out``: ``frame_0.png`` (unloaded) ... ``frame_N.png`` (8-bit grey),
``truth_k.csv`` per load step k (true displacement from the unloaded frame, px, every 8 px in
the tissue), ``manifest.json`` (the image-to-model frame in femu's ``[measurement]`` keys,
loads, mesh, pymust settings, seed, timings). See README.md.
"""

import os

# One core: NumPy's BLAS and femu's rayon pool stay single-threaded unless told otherwise.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field, asdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

SOUND_SPEED = 1540.0  # m/s, pymust's default and the scanners' calibration value

# Acoustic model of the tissues (femu-ultrasound's defaults, tissue.rs): backscatter level
# (dB re muscle) per region; the interfaces' specular echoes (dB re muscle).
ECHO_DB = {
    "FAT": -8.0,
    "QUADRICEPS": 0.0,
    "ISCHIO": 1.0,
    "SARTORIUS": -1.0,
    "GRACILIS": 0.5,
}
DEFAULT_ECHO_DB = 0.0
SKIN_ECHO_DB = 10.0
FASCIA_ECHO_DB = 12.0
BONE_ECHO_DB = 22.0


@dataclass
class Settings:
    """Everything a realization depends on besides the seed (written to manifest.json)."""

    # Probe window (femu's [probe] defaults).
    width_mm: float = 40.0
    depth_mm: float = 40.0
    px_per_mm: float = 10.0
    side: str = "anterior"
    # FE truth.
    elements: int = 16000
    steps: int = 4
    force_n_per_mm: float = 0.1
    # Transducer (pymust param): a 9 MHz linear array like the Logiq E9's ML6-15 at 9 MHz.
    fc_mhz: float = 9.0
    pitch_mm: float = 0.3
    kerf_mm: float = 0.03
    n_elements: int = 134
    bandwidth_pct: float = 75.0
    rx_fnumber: float = 2.5
    # Receive apodization across the f-number aperture: "none" (pymust's dasmtx: every
    # element within depth / (2 f-number) of the pixel with weight 1, a hard edge) or "hann"
    # (weight cos^2(pi dx f-number / depth), zero at the aperture's edge, as scanners do).
    rx_apodization: str = "none"
    angles_deg: list = field(default_factory=lambda: [0.0])
    # pymust's own "quick" settings (pfield isQuick): -20 dB spectrum threshold, one segment
    # per element, frequency step x 1.5 (no time aliasing: the period stays 1.33 x the
    # longest round trip).
    db_thresh: float = -20.0
    element_splitting: int = 1
    frequency_step: float = 1.5
    chunk: int = 1000
    # Phantom.
    muscle_density_per_mm2: float = 150.0
    fat_density_per_mm2: float = 140.0
    line_density_per_mm: float = 20.0
    texture_sigma_mm: float = 0.6
    texture_db: float = 3.0
    margin_mm: float = 1.5
    decorrelation: float = 0.0
    # Display.
    dynamic_db: float = 42.0
    muscle_grey: float = 115.0

    @property
    def size_px(self):
        return (
            int(round(self.width_mm * self.px_per_mm)),
            int(round(self.depth_mm * self.px_per_mm)),
        )


def small_settings() -> Settings:
    """A 64 x 64 px window on a coarse mesh with a few hundred scatterers (CI)."""
    return Settings(
        width_mm=6.4,
        depth_mm=6.4,
        elements=1500,
        steps=2,
        n_elements=26,
        muscle_density_per_mm2=12.0,
        fat_density_per_mm2=10.0,
        line_density_per_mm=4.0,
    )


class InputError(Exception):
    """Bad input: a message naming the option or file."""


# ----------------------------------------------------------------------------------------
# FE solution (femu's Python package)
# ----------------------------------------------------------------------------------------


def solve_fe(s: Settings, cache: Path = None, log=print) -> dict:
    """The built-in thigh at ``s.elements`` elements, solved for the compression test at each
    load fraction k/steps: nodes, quads, region per element, region names, skin faces and
    ``u[k]`` (nodes x 2, mm) for k = 1..steps. Read from ``cache`` (npz) when it holds the same
    mesh and loads, and written to it otherwise."""
    loads = [s.force_n_per_mm * k / s.steps for k in range(1, s.steps + 1)]
    key = f"elements={s.elements};side={s.side};loads={','.join(f'{v:.9g}' for v in loads)}"
    if cache is not None and cache.exists():
        d = np.load(cache, allow_pickle=False)
        if str(d["key"]) == key:
            log(f"FE solution read from {cache}")
            return {k: d[k] for k in d.files} | {"key": key, "loads": loads, "seconds": 0.0}
        log(f"{cache} holds another FE problem ({d['key']}); solving again")
    try:
        import femu
    except ImportError as e:
        raise InputError(
            "the FE truth needs femu's Python package (build it with .ci/python, or "
            "`maturin build --release -m crates/femu-py/Cargo.toml` and pip install the wheel): "
            f"{e}"
        )
    t0 = time.time()
    model = femu.Model.thigh(elements=s.elements)
    elements = np.asarray(model.elements)
    if (elements[:, 3] < 0).any():
        raise InputError("the mesh has triangles: this script locates points in quads only")
    us = []
    for k, f in enumerate(loads):
        sol = model.solve({"kind": "compression", "side": s.side, "force_n_per_mm": f})
        us.append(np.asarray(sol.u)[: len(model.nodes), :2])
        log(f"FE: load {f:.4g} N/mm ({k + 1}/{len(loads)}) solved, max |u| "
            f"{np.hypot(us[-1][:, 0], us[-1][:, 1]).max():.3f} mm")
    out = {
        "nodes": np.asarray(model.nodes),
        "elements": elements,
        "regions": np.asarray(model.element_regions),
        "region_names": np.array(model.region_names),
        "skin": np.asarray(model.skin),
        "u": np.stack(us),
    }
    seconds = time.time() - t0
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(tmp, key=key, **out)
        os.replace(tmp, cache)
    return out | {"key": key, "loads": loads, "seconds": seconds}


# ----------------------------------------------------------------------------------------
# Probe geometry (femu_ultrasound::probe)
# ----------------------------------------------------------------------------------------


@dataclass
class Probe:
    """femu's linear probe: pixel (i, j) images c + ((i + 1/2)/p - W/2) t + ((j + 1/2)/p) n."""

    centre_mm: np.ndarray
    direction: np.ndarray
    width_mm: float
    depth_mm: float
    px_per_mm: float

    @property
    def lateral(self):
        return np.array([-self.direction[1], self.direction[0]])

    @property
    def size_px(self):
        return (
            max(1, int(round(self.width_mm * self.px_per_mm))),
            max(1, int(round(self.depth_mm * self.px_per_mm))),
        )

    def half_width(self):
        return 0.5 * self.size_px[0] / self.px_per_mm

    def model_to_probe(self, x):
        d = np.asarray(x) - self.centre_mm
        return np.stack([d @ self.lateral, d @ self.direction], axis=-1)

    def probe_to_model(self, q):
        q = np.asarray(q)
        return self.centre_mm + q[..., :1] * self.lateral + q[..., 1:2] * self.direction

    def pixel_to_probe(self, p):
        p = np.asarray(p, dtype=float)
        return np.stack(
            [(p[..., 0] + 0.5) / self.px_per_mm - self.half_width(),
             (p[..., 1] + 0.5) / self.px_per_mm], axis=-1)

    def pixel_to_model(self, p):
        return self.probe_to_model(self.pixel_to_probe(p))

    def displacement_to_pixels(self, u_mm):
        u = np.asarray(u_mm)
        return self.px_per_mm * np.stack([u @ self.lateral, u @ self.direction], axis=-1)


def side_direction(side: str) -> np.ndarray:
    deg = {"lateral": 0.0, "anterior": 90.0, "medial": 180.0, "posterior": 270.0}.get(side)
    if deg is None:
        try:
            deg = float(side)
        except ValueError:
            raise InputError(f"--side '{side}': anterior, posterior, lateral, medial or degrees")
    a = np.radians(deg)
    return np.array([np.cos(a), np.sin(a)])


def face_nodes(elements, e, f):
    return elements[e, f % 4], elements[e, (f + 1) % 4]


def probe_on_skin(nodes, elements, skin, s: Settings) -> Probe:
    """femu_ultrasound::probe::probe_on_skin: along the ray from the centre of the skin nodes
    towards the side, at the outermost crossing of the skin faces, beam pointing back."""
    pts = np.array([nodes[k] for e, f in skin for k in face_nodes(elements, e, f)])
    c = pts.mean(axis=0)
    d = side_direction(s.side)
    best = None
    for e, f in skin:
        a, b = face_nodes(elements, e, f)
        p, q = nodes[a], nodes[b]
        sv = q - p
        den = d[0] * sv[1] - d[1] * sv[0]
        if abs(den) < 1e-300:
            continue
        ap = p - c
        t = (ap[0] * sv[1] - ap[1] * sv[0]) / den
        u = (ap[0] * d[1] - ap[1] * d[0]) / den
        if t > 0 and 0 <= u <= 1:
            best = t if best is None else max(best, t)
    if best is None:
        raise InputError(f"no skin face along {d} from the section's centre {c}")
    return Probe(c + best * d, -d, s.width_mm, s.depth_mm, s.px_per_mm)


# ----------------------------------------------------------------------------------------
# Point location in the quads (bilinear shape functions, as femu's PointLocator)
# ----------------------------------------------------------------------------------------


class Locator:
    def __init__(self, nodes, elements):
        from scipy.spatial import cKDTree

        self.nodes = nodes
        self.quads = elements[:, :4]
        self.xy = nodes[self.quads]  # E x 4 x 2
        self.tree = cKDTree(self.xy.mean(axis=1))

    def _inverse(self, e, x):
        """(xi, eta) of the points x in the quads e (Newton from the centre)."""
        X = self.xy[e]
        xi = np.zeros(len(e))
        eta = np.zeros(len(e))
        sx = np.array([-1.0, 1.0, 1.0, -1.0])
        sy = np.array([-1.0, -1.0, 1.0, 1.0])
        for _ in range(12):
            n = 0.25 * (1 + sx * xi[:, None]) * (1 + sy * eta[:, None])
            dnx = 0.25 * sx * (1 + sy * eta[:, None])
            dny = 0.25 * sy * (1 + sx * xi[:, None])
            r = np.einsum("pk,pkc->pc", n, X) - x
            j11 = np.einsum("pk,pk->p", dnx, X[:, :, 0])
            j12 = np.einsum("pk,pk->p", dny, X[:, :, 0])
            j21 = np.einsum("pk,pk->p", dnx, X[:, :, 1])
            j22 = np.einsum("pk,pk->p", dny, X[:, :, 1])
            det = j11 * j22 - j12 * j21
            det = np.where(np.abs(det) < 1e-300, 1e-300, det)
            xi = np.clip(xi - (j22 * r[:, 0] - j12 * r[:, 1]) / det, -3, 3)
            eta = np.clip(eta - (-j21 * r[:, 0] + j11 * r[:, 1]) / det, -3, 3)
        return xi, eta

    def locate(self, x, k=12, tol=1e-7):
        """Element (-1 outside the mesh) and local coordinates of the points x."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        n = len(x)
        elem = np.full(n, -1)
        xi = np.zeros(n)
        eta = np.zeros(n)
        if n == 0:
            return elem, xi, eta
        _, cand = self.tree.query(x, k=min(k, len(self.quads)))
        cand = np.atleast_2d(cand)
        for r in range(cand.shape[1]):
            todo = np.nonzero(elem < 0)[0]
            if len(todo) == 0:
                break
            e = cand[todo, r]
            a, b = self._inverse(e, x[todo])
            inside = (np.abs(a) <= 1 + tol) & (np.abs(b) <= 1 + tol)
            sel = todo[inside]
            elem[sel], xi[sel], eta[sel] = e[inside], a[inside], b[inside]
        return elem, xi, eta

    def interpolate(self, u, elem, xi, eta):
        """The nodal field u (nodes x c) at located points (0 outside)."""
        sx = np.array([-1.0, 1.0, 1.0, -1.0])
        sy = np.array([-1.0, -1.0, 1.0, 1.0])
        ok = elem >= 0
        out = np.zeros((len(elem),) + u.shape[1:])
        n = 0.25 * (1 + sx * xi[ok, None]) * (1 + sy * eta[ok, None])
        out[ok] = np.einsum("pk,pkc->pc", n, u[self.quads[elem[ok]]])
        return out


# ----------------------------------------------------------------------------------------
# Phantom: scatterers in the reference configuration
# ----------------------------------------------------------------------------------------


@dataclass
class Phantom:
    x_ref: np.ndarray  # N x 2, model frame (mm)
    amp: np.ndarray  # N, reflection coefficient (before the renewal of decorrelation)
    level: np.ndarray  # N, amplitude scale (RMS of amp) of each scatterer
    kind: np.ndarray  # N, 0 diffuse, 1 skin, 2 fascia, 3 bone
    elem: np.ndarray
    xi: np.ndarray
    eta: np.ndarray


def region_echo_db(names):
    return np.array([ECHO_DB.get(str(n).upper(), DEFAULT_ECHO_DB) for n in names])


def smooth_field(rng, lo, hi, sigma_mm, h=0.1):
    """A Gaussian random field of unit variance and correlation length sigma_mm over the box
    [lo, hi] (mm), as a function of model points (bilinear on an h-mm grid)."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    n = np.ceil((hi - lo) / h).astype(int) + 1
    g = gaussian_filter(rng.standard_normal((n[1], n[0])), sigma_mm / h, mode="wrap")
    g /= g.std() if g.std() > 0 else 1.0

    def at(x):
        c = (np.asarray(x) - lo) / h
        return map_coordinates(g, [c[:, 1], c[:, 0]], order=1, mode="nearest")

    return at


def make_phantom(rng, fe, loc: Locator, probe: Probe, s: Settings) -> Phantom:
    nodes, elements, regions = fe["nodes"], fe["elements"], fe["regions"]
    names = [str(n) for n in fe["region_names"]]
    echo = region_echo_db(names)
    is_fat = np.array([n.upper() == "FAT" for n in names])
    umax = float(np.hypot(fe["u"][..., 0], fe["u"][..., 1]).max())
    # The reference region whose scatterers can enter the window at some load step.
    m = s.margin_mm + umax
    lo_q = np.array([-probe.half_width() - m, -m])
    hi_q = np.array([probe.half_width() + m, probe.size_px[1] / probe.px_per_mm + m])
    area = np.prod(hi_q - lo_q)
    rho_max = max(s.muscle_density_per_mm2, s.fat_density_per_mm2)
    n = rng.poisson(rho_max * area)
    q = lo_q + rng.random((n, 2)) * (hi_q - lo_q)
    x = probe.probe_to_model(q)
    elem, xi, eta = loc.locate(x)
    inside = elem >= 0
    x, elem, xi, eta = x[inside], elem[inside], xi[inside], eta[inside]
    reg = regions[elem]
    rho = np.where(is_fat[reg], s.fat_density_per_mm2, s.muscle_density_per_mm2)
    keep = rng.random(len(x)) * rho_max < rho
    x, elem, xi, eta, reg, rho = x[keep], elem[keep], xi[keep], eta[keep], reg[keep], rho[keep]
    # Mean backscattered power per unit area 10^(echo/10): amplitude RMS sqrt(10^(echo/10)/rho).
    level = np.sqrt(10 ** (echo[reg] / 10) / rho)
    # Muscle texture: a smooth log-normal modulation (fibre bundles), moving with the tissue.
    lo_m, hi_m = x.min(axis=0) - 1, x.max(axis=0) + 1
    tex = smooth_field(rng, lo_m, hi_m, s.texture_sigma_mm)(x) if len(x) else np.zeros(0)
    level = level * np.where(is_fat[reg], 1.0, 10 ** (s.texture_db * tex / 20))
    kind = np.zeros(len(x), dtype=int)

    # Specular lines: skin, fascia between regions, bone surface (faces of the mesh).
    faces = {}
    for e in range(len(elements)):
        for f in range(4):
            a, b = face_nodes(elements, e, f)
            faces.setdefault((min(a, b), max(a, b)), []).append((e, f))
    skin = {(int(e), int(f)) for e, f in fe["skin"]}
    # Line amplitude: a line of density L per mm seen over the axial cell (~c/(2 B)) has the
    # mean power per unit area 10^(echo/10) when amp RMS = sqrt(10^(echo/10) * w_ax / L).
    w_ax = SOUND_SPEED * 1e3 / (2 * s.bandwidth_pct / 100 * s.fc_mhz * 1e6)
    lx, llev, lkind = [], [], []
    in_box = lambda p: np.all((probe.model_to_probe(p) >= lo_q) & (probe.model_to_probe(p) <= hi_q))  # noqa: E731
    for key in sorted(faces):
        owners = faces[key]
        e, f = owners[0]
        if len(owners) == 1:
            kd, edb = (1, SKIN_ECHO_DB) if (e, f) in skin else (3, BONE_ECHO_DB)
        elif regions[owners[0][0]] != regions[owners[1][0]]:
            kd, edb = 2, FASCIA_ECHO_DB
        else:
            continue
        pa, pb = nodes[key[0]], nodes[key[1]]
        if not (in_box(pa) or in_box(pb)):
            continue
        dv = pb - pa
        ln = np.hypot(*dv)
        if ln <= 0:
            continue
        normal = np.array([dv[1], -dv[0]]) / ln
        cos = abs(normal @ probe.direction)
        spec = np.sqrt(0.1 + 0.9 * cos**4)
        cnt = rng.poisson(s.line_density_per_mm * ln)
        t = rng.random(cnt)
        lx.append(pa + t[:, None] * dv)
        llev.append(np.full(cnt, np.sqrt(10 ** (edb / 10) * w_ax / s.line_density_per_mm) * spec))
        lkind.append(np.full(cnt, kd))
    if lx:
        lx = np.concatenate(lx)
        le, lxi, leta = loc.locate(lx)
        ok = le >= 0  # a point on the outline a rounding error outside is dropped
        x = np.concatenate([x, lx[ok]])
        level = np.concatenate([level, np.concatenate(llev)[ok]])
        kind = np.concatenate([kind, np.concatenate(lkind)[ok]])
        elem = np.concatenate([elem, le[ok]])
        xi = np.concatenate([xi, lxi[ok]])
        eta = np.concatenate([eta, leta[ok]])
    amp = rng.standard_normal(len(x)) * level
    return Phantom(x, amp, level, kind, elem, xi, eta)


# ----------------------------------------------------------------------------------------
# pymust rendering
# ----------------------------------------------------------------------------------------


def pymust_param(s: Settings):
    import pymust

    p = pymust.utils.Param()
    p.fc = s.fc_mhz * 1e6
    p.pitch = s.pitch_mm * 1e-3
    p.kerf = s.kerf_mm * 1e-3
    p.width = p.pitch - p.kerf
    p.Nelements = int(s.n_elements)
    p.bandwidth = s.bandwidth_pct
    p.c = SOUND_SPEED
    p.fs = 4 * p.fc
    p.radius = np.inf
    p.attenuation = 0.0
    return p


def pymust_options(s: Settings):
    import pymust

    o = pymust.utils.Options()
    o.dBThresh = s.db_thresh
    o.ElementSplitting = s.element_splitting
    o.FrequencyStep = s.frequency_step
    o.WaitBar = False
    o.ParPool = False
    return o


class Renderer:
    """pymust on a fixed pixel grid: simus per transmit angle (scatterers in chunks, with two
    silent scatterers at the far corners so every chunk has the same frequency samples and RF
    length), rf2iq, and one DAS matrix per angle (dasmtx, built once)."""

    def __init__(self, s: Settings, width_px: int, height_px: int, z0_mm: float = 0.0):
        import pymust

        # pymust warns through logging on every call with FrequencyStep > 1 (its message is
        # mis-formatted); the choice is deliberate (see Settings).
        logging.getLogger().setLevel(logging.ERROR)
        self.pm = pymust
        self.s = s
        self.w, self.h = width_px, height_px
        self.param = pymust_param(s)
        self.options = pymust_options(s)
        mm = 1e-3
        l = ((np.arange(width_px) + 0.5) / s.px_per_mm - 0.5 * width_px / s.px_per_mm) * mm
        d = (z0_mm + (np.arange(height_px) + 0.5) / s.px_per_mm) * mm
        self.X, self.Z = np.meshgrid(l, d)  # rows: depth, columns: lateral
        self.x_lim = 0.5 * width_px / s.px_per_mm + s.margin_mm  # mm
        self.z_max = z0_mm + height_px / s.px_per_mm + s.margin_mm
        self.delays = [pymust.txdelay(self.param, np.radians(a)) for a in s.angles_deg]
        self._das = [None] * len(self.delays)
        self.aperture = None
        self.seconds = {"simus": 0.0, "rf2iq": 0.0, "dasmtx": 0.0, "das": 0.0}

    def in_view(self, q):
        """Scatterers (probe coordinates, mm) that can echo into the window."""
        return (np.abs(q[:, 0]) <= self.x_lim) & (q[:, 1] > 0.05) & (q[:, 1] <= self.z_max)

    def rf(self, q, rc, k):
        """RF signals (time x elements) of the scatterers q (probe coordinates, mm) with
        reflection coefficients rc for transmit k."""
        pm, mm = self.pm, 1e-3
        far = np.array([[-self.x_lim - 0.5, self.z_max + 0.5], [self.x_lim + 0.5, self.z_max + 0.5]])
        total = None
        for i in range(0, max(len(q), 1), self.s.chunk):
            qc = np.concatenate([q[i:i + self.s.chunk], far])
            rcc = np.concatenate([rc[i:i + self.s.chunk], [0.0, 0.0]])
            out = pm.simus(
                (qc[:, 0] * mm).reshape(1, -1),
                (qc[:, 1] * mm).reshape(1, -1),
                rcc.reshape(1, -1).astype(float),
                self.delays[k],
                self.param.copy(),
                self.options.copy(),
            )
            rf = out[0] if isinstance(out, tuple) else out
            if total is None:
                total = np.array(rf, dtype=np.float64)
            elif rf.shape != total.shape:
                raise RuntimeError(f"simus returned {rf.shape} RF samples after {total.shape}")
            else:
                total += rf
        return total

    def iq_image(self, q, rc):
        """Beamformed complex image (rows: depth) of the scatterers, compounded over the angles."""
        img = np.zeros(self.X.shape, dtype=complex)
        for k in range(len(self.delays)):
            t = time.time()
            rf = self.rf(q, rc, k)
            self.seconds["simus"] += time.time() - t
            t = time.time()
            iq = self.pm.rf2iq(rf, self.param)
            self.seconds["rf2iq"] += time.time() - t
            if self._das[k] is None:
                t = time.time()
                p = self.param.copy()
                p.fnumber = self.s.rx_fnumber
                m = self.pm.dasmtx(1j * np.array(iq.shape), self.X, self.Z, self.delays[k], p)
                m, gain = apodize(m, iq.shape[0], self.X, self.Z, self.param, self.s)
                self._das[k] = (iq.shape, m)
                self.seconds["dasmtx"] += time.time() - t
                if self.aperture is None:
                    self.aperture = gain
            shape, m = self._das[k]
            if iq.shape != shape:
                raise RuntimeError(f"RF of {iq.shape} samples for a DAS matrix of {shape}")
            t = time.time()
            img += (m @ iq.flatten(order="F")).reshape(self.X.shape, order="F")
            self.seconds["das"] += time.time() - t
        # Aperture growth: the receive aperture (f-number) sums n(x) elements, so the mean
        # speckle intensity of a uniform medium grows as n(x); a scanner's gain compensates it
        # (its TGC sliders are set for a uniform image). Divide by sqrt(n).
        return img / np.where(self.aperture > 0, np.sqrt(self.aperture), 1.0)


def apodize(m, samples, X, Z, param, s: Settings):
    """The DAS matrix m with the receive apodization of ``s.rx_apodization`` applied to its
    entries, and each pixel's sum of squared element weights: the factor by which the mean
    speckle intensity of a uniform medium grows with the aperture (the element count without
    apodization), that the image is divided by the square root of."""
    if s.rx_apodization == "none":
        return m, receive_elements(m, samples, X.shape)
    import scipy.sparse as sp

    c = sp.coo_matrix(m)
    element = c.col // samples
    xe = (np.arange(param.Nelements) - 0.5 * (param.Nelements - 1)) * param.pitch
    x, z = X.flatten(order="F"), Z.flatten(order="F")
    dx = np.abs(xe[element] - x[c.row])
    half = z[c.row] / (2.0 * s.rx_fnumber)
    w = np.cos(0.5 * np.pi * np.minimum(dx / np.maximum(half, 1e-12), 1.0)) ** 2
    out = sp.csr_matrix((c.data * w, (c.row, c.col)), shape=m.shape)
    # One weight per (pixel, element): the first entry of each pair.
    pe = np.unique(c.row.astype(np.int64) * param.Nelements + element, return_index=True)[1]
    gain = np.bincount(c.row[pe], weights=w[pe] ** 2, minlength=m.shape[0])
    return out, gain.reshape(X.shape, order="F")


def receive_elements(m, samples, shape):
    """Number of array elements the DAS matrix m sums at each pixel (columns are element-major
    IQ samples, as iq.flatten(order="F"))."""
    import scipy.sparse as sp

    c = sp.coo_matrix(m)
    e = sp.csr_matrix((np.ones(c.nnz), (c.row, c.col // samples)), shape=(m.shape[0], c.col.max() // samples + 1 if c.nnz else 1))
    e.sum_duplicates()
    return np.diff(e.indptr).reshape(shape, order="F").astype(float)


def to_grey(envelope, black_db, dynamic_db):
    level = 20 * np.log10(np.maximum(envelope, 1e-300))
    return np.clip(np.round(255 * (level - black_db) / dynamic_db), 0, 255).astype(np.uint8)


def save_png(path: Path, grey: np.ndarray):
    from PIL import Image

    tmp = path.with_name(path.stem + ".tmp.png")
    Image.fromarray(grey, mode="L").save(tmp)
    os.replace(tmp, path)


def phase_correlation(a, b):
    """Shift (dx, dy) in px of image b relative to a (b(x) ~ a(x - d)), sub-pixel by a
    parabola through the correlation peak and its neighbours."""
    a = (a - a.mean()) * np.outer(np.hanning(a.shape[0]), np.hanning(a.shape[1]))
    b = (b - b.mean()) * np.outer(np.hanning(b.shape[0]), np.hanning(b.shape[1]))
    fa, fb = np.fft.fft2(a), np.fft.fft2(b)
    r = fb * np.conj(fa)
    r /= np.maximum(np.abs(r), 1e-30)
    c = np.real(np.fft.ifft2(r))
    j, i = np.unravel_index(np.argmax(c), c.shape)
    h, w = c.shape

    def sub(cm, c0, cp):
        den = cm - 2 * c0 + cp
        return 0.0 if den == 0 else 0.5 * (cm - cp) / den

    dx = i + sub(c[j, (i - 1) % w], c[j, i], c[j, (i + 1) % w])
    dy = j + sub(c[(j - 1) % h, i], c[j, i], c[(j + 1) % h, i])
    dx = dx - w if dx > w / 2 else dx
    dy = dy - h if dy > h / 2 else dy
    return float(dx), float(dy)


# ----------------------------------------------------------------------------------------
# One realization
# ----------------------------------------------------------------------------------------


def write_truth(path: Path, pts_px, u_px):
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as f:
        f.write("x_px,y_px,ux_px,uy_px\n")
        for p, u in zip(pts_px, u_px):
            f.write(f"{p[0]:.1f},{p[1]:.1f},{u[0]:.6f},{u[1]:.6f}\n")
    os.replace(tmp, path)


_RENDERERS = {}


def realization(seed: int, out: Path, s: Settings, fe_cache: Path = None, log=print) -> dict:
    t_start = time.time()
    c_start = time.process_time()
    out.mkdir(parents=True, exist_ok=True)
    fe = solve_fe(s, fe_cache, log)
    t_fe = time.time() - t_start
    nodes, elements = fe["nodes"], fe["elements"]
    probe = probe_on_skin(nodes, elements, fe["skin"], s)
    w, h = probe.size_px
    loc = Locator(nodes, elements)
    rng = np.random.default_rng(seed)
    t = time.time()
    ph = make_phantom(rng, fe, loc, probe, s)
    t_phantom = time.time() - t
    # Positions per state: the unloaded one, then each load step.
    states = [ph.x_ref] + [ph.x_ref + loc.interpolate(u, ph.elem, ph.xi, ph.eta) for u in fe["u"]]
    # One renderer (its DAS matrices) per window and settings, shared by the realizations.
    key = (w, h, json.dumps(asdict(s), sort_keys=True))
    ren = _RENDERERS.get(key)
    if ren is None:
        ren = _RENDERERS[key] = Renderer(s, w, h)
    ren.seconds = dict.fromkeys(ren.seconds, 0.0)
    # Pixels of the reference frame in the tissue (for the truth and the display level).
    jj, ii = np.mgrid[0:h, 0:w]
    pix = np.stack([ii.ravel(), jj.ravel()], axis=1)
    pe, pxi, peta = loc.locate(probe.pixel_to_model(pix))
    names = [str(n).upper() for n in fe["region_names"]]
    fat = np.array([n == "FAT" for n in names])
    muscle_px = (pe >= 0) & ~fat[np.maximum(fe["regions"][pe], 0)]
    amp = ph.amp.copy()
    frames, frame_seconds, n_used = [], [], []
    black_db = None
    for k, x in enumerate(states):
        if k > 0 and s.decorrelation > 0:
            renew = rng.random(len(amp)) < s.decorrelation
            amp[renew] = rng.standard_normal(renew.sum()) * ph.level[renew]
        t = time.time()
        q = probe.model_to_probe(x)
        v = ren.in_view(q)
        env = np.abs(ren.iq_image(q[v], amp[v]))
        if black_db is None:
            # The gain of the unloaded frame, kept for every frame: the muscle's RMS envelope
            # at grey `muscle_grey` (femu's default gain puts it at 115).
            ref = env.ravel()[muscle_px] if muscle_px.any() else env.ravel()
            rms_db = 10 * np.log10(np.mean(ref**2))
            black_db = rms_db - s.dynamic_db * s.muscle_grey / 255
        grey = to_grey(env, black_db, s.dynamic_db)
        save_png(out / f"frame_{k}.png", grey)
        frames.append(f"frame_{k}.png")
        frame_seconds.append(time.time() - t)
        n_used.append(int(v.sum()))
        log(f"seed {seed}: frame {k} ({int(v.sum())} scatterers) in {frame_seconds[-1]:.1f} s")
    # Truth every 8 px in the tissue of the reference frame.
    step = 8
    gj, gi = np.mgrid[0:h:step, 0:w:step]
    g = np.stack([gi.ravel(), gj.ravel()], axis=1).astype(float)
    ge, gxi, geta = loc.locate(probe.pixel_to_model(g))
    ok = ge >= 0
    truth = []
    for k, u in enumerate(fe["u"], start=1):
        u_px = probe.displacement_to_pixels(loc.interpolate(u, ge[ok], gxi[ok], geta[ok]))
        write_truth(out / f"truth_{k}.csv", g[ok], u_px)
        truth.append(f"truth_{k}.csv")
    manifest = {
        "generator": "bench/independent_us/render_pymust.py (pymust, the Python MUST/SIMUS toolbox)",
        "seed": seed,
        "frames": frames,
        "truth": truth,
        "image_px": [w, h],
        "loads_n_per_mm": [0.0] + [float(v) for v in fe["loads"]],
        "test": f"compression, rigid plate, {s.side}",
        "measurement": {
            "units": "px",
            "pixel_size_mm": 1.0 / s.px_per_mm,
            "origin_mm": [float(v) for v in probe.pixel_to_model(np.array([0.0, 0.0]))],
            "x_axis": [float(v) for v in probe.lateral],
            "y_axis": [float(v) for v in probe.direction],
        },
        "probe": {
            "centre_mm": [float(v) for v in probe.centre_mm],
            "direction": [float(v) for v in probe.direction],
            "width_mm": s.width_mm,
            "depth_mm": s.depth_mm,
            "px_per_mm": s.px_per_mm,
            "pixel_convention": "pixel (i, j) (column, row) has its centre at integer "
            "coordinates and images centre + ((i + 1/2)/p - W/2) x_axis + ((j + 1/2)/p) y_axis",
        },
        "fe": {
            "mesh": "femu built-in thigh, Table 1 materials (femu.Model.thigh)",
            "elements": int(len(elements)),
            "nodes": int(len(nodes)),
            "max_displacement_mm": float(np.hypot(fe["u"][..., 0], fe["u"][..., 1]).max()),
            "solve_seconds": float(fe["seconds"]),
        },
        "pymust": {
            "version": pymust_version(),
            "fc_hz": s.fc_mhz * 1e6,
            "pitch_m": s.pitch_mm * 1e-3,
            "kerf_m": s.kerf_mm * 1e-3,
            "n_elements": s.n_elements,
            "bandwidth_pct": s.bandwidth_pct,
            "fs_hz": 4 * s.fc_mhz * 1e6,
            "c_m_per_s": SOUND_SPEED,
            "attenuation_db_per_cm_mhz": 0.0,
            "transmits": "plane waves, coherent compounding",
            "angles_deg": list(s.angles_deg),
            "rx_fnumber": s.rx_fnumber,
            "rx_apodization": s.rx_apodization,
            "das_interpolation": "linear (dasmtx default)",
            "options": {"dBThresh": s.db_thresh, "ElementSplitting": s.element_splitting,
                        "FrequencyStep": s.frequency_step},
            "dynamic_db": s.dynamic_db,
            "black_level_db": float(black_db),
        },
        "phantom": {
            "scatterers": int(len(ph.x_ref)),
            "scatterers_per_frame": n_used,
            "diffuse": int((ph.kind == 0).sum()),
            "skin_lines": int((ph.kind == 1).sum()),
            "fascia_lines": int((ph.kind == 2).sum()),
            "bone_lines": int((ph.kind == 3).sum()),
            "decorrelation": s.decorrelation,
        },
        "settings": asdict(s),
        "timings_s": {
            "fe": t_fe,
            "phantom": t_phantom,
            "frames": frame_seconds,
            "pymust": ren.seconds,
            "total_wall": time.time() - t_start,
            "total_cpu": time.process_time() - c_start,
        },
    }
    tmp = out / "manifest.tmp.json"
    tmp.write_text(json.dumps(manifest, indent=1))
    os.replace(tmp, out / "manifest.json")
    return manifest


def pymust_version():
    try:
        from importlib.metadata import version

        return version("pymust")
    except Exception:  # noqa: BLE001 - metadata absent in a source checkout
        return "unknown"


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder (seed_NN inside with --seeds)")
    ap.add_argument("--seed", type=int, default=1, help="realization seed (scatterers)")
    ap.add_argument("--seeds", help="several realizations, e.g. 1-10: one sub-folder seed_NN each")
    ap.add_argument("--small", action="store_true", help="a 64 x 64 px run on a coarse mesh (CI)")
    ap.add_argument("--elements", type=int, help="elements of the FE truth (default 16000)")
    ap.add_argument("--steps", type=int, help="load steps (default 4: 5 frames)")
    ap.add_argument("--density", type=float, help="muscle scatterers per mm^2 (default 150)")
    ap.add_argument("--fat-density", type=float, help="fat scatterers per mm^2 (default 140)")
    ap.add_argument("--angles", help="plane-wave angles in degrees, comma-separated (default 0)")
    ap.add_argument("--decorrelation", type=float, default=0.0,
                    help="fraction of the scatterers renewed per load step (default 0)")
    ap.add_argument("--fe-cache", type=Path,
                    help="npz file holding the FE solution (default: fe_cache.npz beside --out)")
    ap.add_argument("--rx-apodization", choices=["none", "hann"], default="none",
                    help="receive apodization over the f-number aperture (default none: "
                         "pymust's dasmtx, a hard-edged aperture)")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    s = small_settings() if a.small else Settings()
    if a.elements is not None:
        if not 100 <= a.elements <= 200000:
            raise InputError(f"--elements {a.elements}: in [100, 200000]")
        s.elements = a.elements
    if a.steps is not None:
        if not 1 <= a.steps <= 20:
            raise InputError(f"--steps {a.steps}: in [1, 20]")
        s.steps = a.steps
    for name, v, attr in [("--density", a.density, "muscle_density_per_mm2"),
                          ("--fat-density", a.fat_density, "fat_density_per_mm2")]:
        if v is not None:
            if not 0 < v <= 10000:
                raise InputError(f"{name} {v}: in (0, 10000] per mm^2")
            setattr(s, attr, v)
    if a.angles:
        try:
            s.angles_deg = [float(v) for v in a.angles.split(",")]
        except ValueError:
            raise InputError(f"--angles '{a.angles}': degrees, comma-separated")
        if any(abs(v) > 30 for v in s.angles_deg):
            raise InputError(f"--angles '{a.angles}': each within [-30, 30] degrees")
    if not 0 <= a.decorrelation <= 0.9:
        raise InputError(f"--decorrelation {a.decorrelation}: in [0, 0.9]")
    s.decorrelation = a.decorrelation
    s.rx_apodization = a.rx_apodization
    seeds = [a.seed]
    if a.seeds:
        try:
            lo, _, hi = a.seeds.partition("-")
            seeds = list(range(int(lo), int(hi or lo) + 1))
        except ValueError:
            raise InputError(f"--seeds '{a.seeds}': a range such as 1-10")
        if not seeds:
            raise InputError(f"--seeds '{a.seeds}': an empty range")
    return a, s, seeds


def main(argv=None):
    try:
        a, s, seeds = parse_args(sys.argv[1:] if argv is None else argv)
        log = (lambda m: None) if a.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
        cache = a.fe_cache or (a.out.parent if not a.seeds else a.out) / (
            f"fe_cache_{s.elements}_{s.steps}.npz")
        for seed in seeds:
            out = a.out / f"seed_{seed:02d}" if a.seeds else a.out
            m = realization(seed, out, s, cache, log)
            log(f"seed {seed}: {len(m['frames'])} frames in {m['timings_s']['total_wall']:.1f} s "
                f"(cpu {m['timings_s']['total_cpu']:.1f} s) -> {out}")
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: the finished realizations are kept", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
