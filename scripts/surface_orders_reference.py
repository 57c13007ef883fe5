#!/usr/bin/env python3
"""The scored reference of issue 24 (item 4 and its Targets): ``orders="surface"`` and
``orders="seed"`` against explicit random microsurfaces traced with seeds of their own,
by bounce order, over roughness, incidence, exit geometry, material and the shape of the
surface's autocorrelation. Writes docs/surface-orders-reference.md and prints it.

    python scripts/surface_orders_reference.py [--quick] [--alphas 0.3,0.5] [--thetas 0,30]
        [--materials glass,aluminium] [--correlations gaussian,matern] [--max-rays N]
        [--se-target 0.03] [--budget-s S] [--no-trace] [--bank-rays N]
        [--cache DIR] [--out docs/surface-orders-reference.md]

The grid: alpha 0.05-1.0, incidence 0-70 deg, four exit directions (backscatter; 15 and 30
deg bistatic in the plane of incidence, toward the normal; 30 deg bistatic across it),
glass and two metals, two autocorrelation shapes with the same Gaussian slope statistics
(the reference's own Gaussian synthesis, and a Matern of smoothness 5/2 synthesized here),
orders 1, 2, 3+ and the whole return at backscatter; incoherent throughout (the model with
``coherent_backscatter=False``).

A cell (shape, alpha, material, incidence) is traced in calls of a fixed number of rays on
a fixed number of fresh surfaces each; the calls are the independent units (standard
errors from their spread; the delta method for normalized elements, the jackknife for the
depolarization index). A cell is traced until the reference's standard error of M00 is at
most ``--se-target`` (3%) of M00 in every row that a target needs (order 2 where it exceeds
1% of order 1; orders 3+; the whole return at backscatter), leaving out rows whose
projected cost exceeds ``--max-rays``, or until the cell has ``--max-rays`` rays. The
per-call estimates, their seeds and rays are saved after every chunk of calls in
``--cache`` (one file per cell and tally configuration, written atomically), so a rerun
continues where the last one stopped and traces only cells whose target is not yet met;
a cache file whose configuration differs, or that cannot be read, is traced anew.

Seeds: call ``k`` of a cell uses ``SEED_BASE + crc32(cell) * 100000 + k`` (about 7e15):
none of the development scripts' seeds (below 1e7) and none of the path banks' (seed 1,
their own streams).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
import zlib
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import compare_microsurface as cm  # noqa: E402  (cone averaging in the reference's bases, estimators)
from bank_vs_surface import depol  # noqa: E402

import pprender  # noqa: E402
from pprender import reference  # noqa: E402

ALPHAS = (0.05, 0.1, 0.2, 0.3, 0.5, 0.8, 1.0)
THETAS = (0.0, 30.0, 50.0, 70.0)
# eta at 1064 nm as pprender.materials tabulates it (the sources are named there).
MATERIALS: Dict[str, complex] = {
    "glass": 1.5 + 0j,
    "aluminium": 1.3763 + 10.2449j,  # Rakic 1995, Appl. Opt. 34, 4755
    "gold": 0.2585 + 6.9654j,  # Johnson & Christy 1972, Phys. Rev. B 6, 4370
}
CORRELATIONS = ("gaussian", "matern")
# name, bistatic angle (deg), azimuth about wi (pprender.reference.bistatic_directions:
# 0 tilts in the plane of incidence away from the normal, pi toward it, pi/2 across it)
EXITS: Tuple[Tuple[str, float, float], ...] = (
    ("bs", 0.0, 0.0),
    ("in15", 15.0, math.pi),
    ("in30", 30.0, math.pi),
    ("out30", 30.0, math.pi / 2),
)
SURFACE_RANGE = (0.05, 1.0)  # orders="surface" exists here only
MODES = ("surface", "seed")
# Tolerances of the issue's Targets.
TOL = {"o2_m00": 0.10, "o2_norm": 0.05, "o3_m00": 0.25, "o3_di": 0.10, "whole_di": 0.03}
TARGET_NAMES = {
    "o2_m00": "order 2 M00 (10%)",
    "o2_norm": "order 2 M/M00 (0.05)",
    "o3_m00": "3+ M00 (25%)",
    "o3_di": "3+ DI (0.1)",
    "whole_di": "whole DI at bs (0.03)",
}
ORDER2_MIN = 0.01  # order 2 is scored where it exceeds this fraction of order 1
CORR_LENGTH = 8.0  # the Gaussian's C(r) = exp(-r^2 / l^2), grid units
MATERN_NU = 2.5
# Matern C(r) = (1 + sqrt(5) r / L + 5 r^2 / (3 L^2)) exp(-sqrt(5) r / L): -C''(0) = nu / ((nu - 1) L^2),
# equal to the Gaussian's 2 / l^2 for this L: the same height rms gives the same slope rms.
MATERN_LENGTH = CORR_LENGTH * math.sqrt(MATERN_NU / (2.0 * (MATERN_NU - 1.0)))
SEED_BASE = 7_000_000_000_000_000
CACHE_VERSION = 1
FINE = (6, 24)  # cone rule for order 1 (narrow lobes at small alpha)
# Cone rules for orders >= 2: the seed's double term is smooth across a 0.1 rad cone (and costs
# ~15 ms a point); the path-bank tables are cheap and less smooth (at alpha 1, 70 deg, order 2
# moved by up to 20% from (2, 8) to (5, 20) with a small bank).
COARSE = (2, 8)
SURFACE_RULE = (5, 20)
MIN_COUNTS = 10  # a row with fewer rays in the cone has no usable standard error yet
DEFAULT_CACHE = Path.home() / ".cache" / "pprender" / "surface-orders-reference"
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "docs" / "surface-orders-reference.md"


@dataclass(frozen=True)
class Settings:
    rays_per_call: int  # primary rays per call (all its surfaces together)
    surfaces_per_call: int  # fresh surfaces per call
    min_calls: int  # calls before the first standard error is trusted
    max_rays: int  # ray cap per cell
    se_target: float  # relative standard error of M00 to reach (and to score)
    grid: int
    cone: float
    max_order: int
    bank_rays: Optional[int]  # the model's path-bank rays per incidence node (None: its default)


FULL = Settings(rays_per_call=400_000, surfaces_per_call=8, min_calls=8, max_rays=40_000_000,
                se_target=0.03, grid=256, cone=0.1, max_order=20, bank_rays=None)
QUICK = Settings(rays_per_call=20_000, surfaces_per_call=2, min_calls=4, max_rays=400_000,
                 se_target=0.03, grid=128, cone=0.1, max_order=20, bank_rays=100_000)


@dataclass(frozen=True)
class Cell:
    correlation: str
    alpha: float
    material: str
    theta: float

    @property
    def key(self) -> str:
        return f"{self.correlation}-a{self.alpha:g}-{self.material}-t{self.theta:g}"

    @property
    def eta(self) -> complex:
        return MATERIALS[self.material]

    @property
    def wi(self) -> np.ndarray:
        return cm.direction(self.theta)

    def wos(self) -> np.ndarray:
        return exit_directions(self.wi)

    def seed(self, k: int) -> int:
        return SEED_BASE + zlib.crc32(self.key.encode()) * 100_000 + k


def exit_directions(wi: np.ndarray) -> np.ndarray:
    """``(len(EXITS), 3)`` detector directions for incidence ``wi``."""
    return np.array([reference.bistatic_directions(wi, math.radians(b), a) for _, b, a in EXITS])


# ----------------------------------------------------------------------------- surfaces
def matern_filter(grid: int, length: float = MATERN_LENGTH, nu: float = MATERN_NU) -> np.ndarray:
    """Amplitude filter of the Matern synthesis: the square root of the 2-D Matern power
    spectrum ``(2 nu / L^2 + |k|^2)^(-(nu + 1))`` (k in radians per grid unit)."""
    k = 2 * math.pi * np.fft.fftfreq(grid)
    kk = k[:, None] ** 2 + k[None, :] ** 2
    return np.asarray((2 * nu / length**2 + kk) ** (-(nu + 1) / 2))


def matern_acf(r: np.ndarray, length: float = MATERN_LENGTH) -> np.ndarray:
    """Normalized Matern (nu = 5/2) autocorrelation at lag ``r`` (grid units)."""
    x = math.sqrt(5.0) * np.asarray(r, float) / length
    return np.asarray((1 + x + x * x / 3) * np.exp(-x))


def slope_alpha(h: np.ndarray) -> float:
    """Beckmann alpha of the reference's triangulation of ``h``: the triangles' slopes are
    the periodic forward differences of the grid, so alpha^2 = mean(dx^2) + mean(dy^2)."""
    dx = np.roll(h, -1, axis=0) - h
    dy = np.roll(h, -1, axis=1) - h
    return float(math.sqrt(np.mean(dx * dx) + np.mean(dy * dy)))


def matern_heights(alpha: float, grid: int, seed: int) -> np.ndarray:
    """A periodic Gaussian random height field with a Matern (nu = 5/2) autocorrelation,
    ``heights[i, j]`` at ``x = i, y = j`` in grid units, white Gaussian noise filtered in
    Fourier space (so every slope component is exactly normal), rescaled like the
    reference's Gaussian synthesis so that the realized alpha of its triangles equals
    ``alpha`` (alpha^2 = 2 var(slope component))."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((grid, grid))
    h = np.fft.ifft2(np.fft.fft2(noise) * matern_filter(grid)).real
    h -= h.mean()
    return np.asarray(h * (alpha / slope_alpha(h)))


# ----------------------------------------------------------------------------- reference
def trace_call(cell: Cell, s: Settings, k: int) -> Dict[str, Any]:
    """Call ``k`` of a cell: ``s.rays_per_call`` rays on ``s.surfaces_per_call`` fresh
    surfaces. Returns the call's estimates ``est (3, nexit, 4, 4)`` (orders 1, 2, 3+),
    ``counts (3, nexit)``, ``albedo (3,)``, ``elapsed``."""
    seed = cell.seed(k)
    wi, wos = cell.wi, cell.wos()
    common: Dict[str, Any] = dict(eta=cell.eta, cone=s.cone, max_order=s.max_order)
    if cell.correlation == "gaussian":
        o = reference.microsurface(wi, wos, alpha=cell.alpha, rays=s.rays_per_call, grid=s.grid,
                                   correlation_length=CORR_LENGTH, seed=seed, batches=s.surfaces_per_call, **common)
        if o["lost"] != 0.0:
            raise RuntimeError(f"{cell.key}: the reference lost rays ({o['lost']})")
        return {"est": o["mueller"], "counts": o["counts"], "albedo": o["albedo"], "elapsed": o["elapsed_s"]}
    if cell.correlation != "matern":
        raise ValueError(f"unknown correlation {cell.correlation!r}")
    per = s.rays_per_call // s.surfaces_per_call
    est, counts, albedo, el = [], [], [], 0.0
    for j in range(s.surfaces_per_call):
        h = matern_heights(cell.alpha, s.grid, seed * 64 + j)
        o = reference.microsurface(wi, wos, heights=h, rays=per, seed=seed * 64 + j, batches=2, **common)
        if o["lost"] != 0.0 or abs(o["realized_alpha"] / cell.alpha - 1) > 1e-9:
            raise RuntimeError(f"{cell.key}: lost {o['lost']}, realized alpha {o['realized_alpha']}")
        est.append(o["mueller"])
        counts.append(o["counts"])
        albedo.append(o["albedo"])
        el += o["elapsed_s"]
    return {"est": np.mean(est, axis=0), "counts": np.sum(counts, axis=0), "albedo": np.mean(albedo, axis=0),
            "elapsed": el}


def tally_meta(cell: Cell, s: Settings) -> Dict[str, Any]:
    """What defines a cell's tally: a cache file with other values is not used."""
    return {
        "version": CACHE_VERSION, "cell": cell.key, "alpha": cell.alpha, "theta": cell.theta,
        "eta": [cell.eta.real, cell.eta.imag], "correlation": cell.correlation,
        "correlation_length": CORR_LENGTH if cell.correlation == "gaussian" else MATERN_LENGTH,
        "nu": MATERN_NU if cell.correlation == "matern" else None,
        "exits": [list(e) for e in EXITS], "rays_per_call": s.rays_per_call,
        "surfaces_per_call": s.surfaces_per_call, "grid": s.grid, "cone": s.cone, "max_order": s.max_order,
        "seed_base": SEED_BASE,
    }


def cache_path(cache: Path, cell: Cell, s: Settings) -> Path:
    meta = json.dumps(tally_meta(cell, s), sort_keys=True)
    return cache / f"{cell.key}-{zlib.crc32(meta.encode()):08x}.npz"


def empty_tally(cell: Cell, s: Settings) -> Dict[str, Any]:
    n = len(EXITS)
    return {"meta": tally_meta(cell, s), "est": np.zeros((0, 3, n, 4, 4)), "counts": np.zeros((0, 3, n), np.int64),
            "albedo": np.zeros((0, 3)), "seeds": np.zeros(0, np.int64), "elapsed": np.zeros(0)}


def load_tally(cache: Path, cell: Cell, s: Settings) -> Dict[str, Any]:
    """The cached tally of a cell, or an empty one (missing, unreadable or another
    configuration: never trusted)."""
    p = cache_path(cache, cell, s)
    t = empty_tally(cell, s)
    if not p.exists():
        return t
    try:
        with np.load(p, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            got = {k: np.asarray(z[k]) for k in ("est", "counts", "albedo", "seeds", "elapsed")}
        kk = len(got["seeds"])
        ok = (meta == t["meta"] and got["est"].shape == (kk,) + t["est"].shape[1:]
              and got["counts"].shape == (kk,) + t["counts"].shape[1:] and got["albedo"].shape == (kk, 3)
              and got["elapsed"].shape == (kk,)
              and np.array_equal(got["seeds"], [cell.seed(k) for k in range(kk)])
              and bool(np.all(np.isfinite(got["est"]))))
    except Exception:  # corrupt or truncated file: traced anew
        ok = False
    if not ok:
        return t
    t.update(got)
    return t


def save_tally(cache: Path, cell: Cell, s: Settings, t: Dict[str, Any]) -> None:
    """Write atomically (a temporary file in the same folder, then a rename)."""
    cache.mkdir(parents=True, exist_ok=True)
    p = cache_path(cache, cell, s)
    fd, tmp = tempfile.mkstemp(dir=cache, prefix=p.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, meta=np.array(json.dumps(t["meta"], sort_keys=True)), est=t["est"], counts=t["counts"],
                     albedo=t["albedo"], seeds=t["seeds"], elapsed=t["elapsed"])
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def jackknife_di(est: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Depolarization index of the mean of ``est (K, ..., 4, 4)`` and its jackknife
    standard error over the K calls."""

    def di(m: np.ndarray) -> np.ndarray:
        m00 = m[..., 0, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(np.maximum(0.0, (np.sum(m * m, axis=(-2, -1)) - m00**2) / (3 * m00**2)))

    kk = est.shape[0]
    full = di(est.mean(axis=0))
    if kk < 2:
        return full, np.full_like(full, np.nan)
    loo = di((est.sum(axis=0)[None] - est) / (kk - 1))
    se = np.sqrt((kk - 1) / kk * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0))
    return full, se


def ref_stats(t: Dict[str, Any]) -> Dict[str, Any]:
    """Estimates of a tally, rows ``(4, nexit)``: orders 1, 2, 3+ and the whole return."""
    est = np.asarray(t["est"])
    kk = est.shape[0]
    allm = np.concatenate([est, est.sum(axis=1, keepdims=True)], axis=1)  # (K, 4, nexit, 4, 4)
    counts = np.asarray(t["counts"])
    cnt = np.concatenate([counts.sum(axis=0), counts.sum(axis=(0, 1))[None]], axis=0)
    mean = allm.mean(axis=0)
    if kk >= 2:
        se = allm.std(axis=0, ddof=1) / math.sqrt(kk)
        norm, norm_se = cm.normalized(allm)
    else:
        se = np.full_like(mean, np.nan)
        norm, norm_se = mean / mean[..., :1, :1], np.full_like(mean, np.nan)
    di, di_se = jackknife_di(allm)
    m00 = mean[..., 0, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(m00 > 0, se[..., 0, 0] / m00, np.inf)
    rel = np.where(cnt >= MIN_COUNTS, rel, np.inf)
    return {"mean": mean, "se": se, "norm": norm, "norm_se": norm_se, "di": di, "di_se": di_se, "rel": rel,
            "counts": cnt, "calls": kk, "rays": kk * int(t["meta"]["rays_per_call"]),
            "elapsed": float(np.sum(t["elapsed"]))}


def needed_rows(st: Dict[str, Any]) -> np.ndarray:
    """``(4, nexit)`` mask of the rows a target needs: order 2 where it exceeds
    ``ORDER2_MIN`` of order 1, orders 3+, the whole return at backscatter."""
    m00 = st["mean"][..., 0, 0]
    need = np.zeros(m00.shape, bool)
    need[1] = m00[1] > ORDER2_MIN * m00[0]
    need[2] = True
    need[3, 0] = True
    return need


def rays_needed(st: Dict[str, Any], s: Settings) -> int:
    """Projected rays for every needed, reachable row to meet the target (se ~ 1/sqrt(rays));
    rows without usable counts or beyond ``s.max_rays`` are left out."""
    proj = st["rays"] * (st["rel"] / s.se_target) ** 2 * 1.1
    open_ = needed_rows(st) & (st["rel"] > s.se_target) & np.isfinite(proj) & (proj <= s.max_rays)
    return int(np.ceil(proj[open_].max())) if open_.any() else 0


def trace_cell(cell: Cell, s: Settings, cache: Path, deadline: float = math.inf,
               log: Callable[[str], None] = print) -> Tuple[Dict[str, Any], int]:
    """Continue a cell's tally from the cache until its target is met, the ray cap or the
    deadline is reached; returns the tally and the rays traced now."""
    t = load_tally(cache, cell, s)
    new = 0
    r = s.rays_per_call
    max_calls = max(s.min_calls, s.max_rays // r)
    while True:
        kk = len(t["seeds"])
        if kk < s.min_calls:
            want = s.min_calls - kk
        else:
            need = rays_needed(ref_stats(t), s)
            want = max(0, math.ceil(need / r) - kk)
        want = min(want, max_calls - kk)
        if want <= 0 or time.time() > deadline:
            break
        for start in range(0, want, 4):  # save after every 4 calls
            if time.time() > deadline:
                break
            calls = [trace_call(cell, s, k) for k in range(kk + start, kk + min(want, start + 4))]
            n0 = len(t["seeds"])
            t["est"] = np.concatenate([t["est"], [c["est"] for c in calls]])
            t["counts"] = np.concatenate([t["counts"], np.array([c["counts"] for c in calls], np.int64)])
            t["albedo"] = np.concatenate([t["albedo"], [c["albedo"] for c in calls]])
            t["seeds"] = np.concatenate([t["seeds"], np.array([cell.seed(n0 + i) for i in range(len(calls))])])
            t["elapsed"] = np.concatenate([t["elapsed"], [c["elapsed"] for c in calls]])
            new += len(calls) * r
            save_tally(cache, cell, s, t)
    if new:
        st = ref_stats(t)
        log(f"{cell.key}: {st['rays']:.2e} rays ({new:.2e} now, {st['elapsed']:.1f} s traced in all), "
            f"se/M00 order 2 {fmt_rel(st['rel'][1])}, 3+ {fmt_rel(st['rel'][2])}")
    return t, new


def fmt_rel(x: np.ndarray) -> str:
    return "/".join("-" if not np.isfinite(v) else f"{v:.1%}" for v in x)


# ----------------------------------------------------------------------------- model
class ConeRule:
    """:func:`compare_microsurface.cone_average` with its nodes, weights and basis
    changes computed once per geometry and reused for every material (same sums)."""

    _cache: Dict[Tuple[Any, ...], "ConeRule"] = {}

    def __init__(self, wi: np.ndarray, wos: Sequence[np.ndarray], cone: float, rule: Tuple[int, int]) -> None:
        self.wi = np.asarray(wi, float)
        pts, pre, post, owner = [], [], [], []
        for i, wo in enumerate(wos):
            wo = np.asarray(wo, float)
            p, wt = cm.cone_points(wo, cone, rule)
            xir, yir, xor_, _ = cm.sp_bases(self.wi, wo)
            for w, x in zip(p, wt):
                xim, yim, xom, yom = cm.sp_bases(self.wi, w)
                xt = cm._transport(xor_, wo, w)
                yt = np.cross(w, xt)
                jo = np.array([[xt @ xom, xt @ yom], [yt @ xom, yt @ yom]])
                ji = np.array([[xim @ xir, xim @ yir], [yim @ xir, yim @ yir]])
                pts.append(w)
                post.append(x * cm.mueller_of(jo))
                pre.append(cm.mueller_of(ji))
                owner.append(i)
        self.pts, self.pre, self.post = np.array(pts), np.array(pre), np.array(post)
        self.owner, self.n = np.array(owner), len(wos)

    @classmethod
    def get(cls, wi: np.ndarray, wos: Sequence[np.ndarray], cone: float, rule: Tuple[int, int]) -> "ConeRule":
        key = (tuple(np.round(wi, 12)), tuple(np.round(np.ravel(wos), 12)), cone, rule)
        if key not in cls._cache:
            cls._cache[key] = cls(wi, wos, cone, rule)
        return cls._cache[key]

    def average(self, evalf: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
        m = evalf(np.broadcast_to(self.wi, self.pts.shape).copy(), self.pts)
        per = np.einsum("nij,njk,nkl->nil", self.post, m, self.pre)
        out = np.zeros((self.n, 4, 4))
        np.add.at(out, self.owner, per)
        return out


_MATS: Dict[Tuple[float, complex, str, Optional[int], str], Optional[Dict[str, pprender.Material]]] = {}
# The terms add up: 3+ is dm - d, and order 1 is sdm - dm. With orders="surface" it must
# be that difference: the single term's masking is calibrated to the bank's order 1 with
# the multiple term's energy balance (Surface::calibrate_masking), which a single-term
# material (no banks) does not have, and dm has the same calibration as sdm. orders="seed"
# has no calibration, so there order 1 is the single-term material "s", which spares the
# seed's double term (~15 ms a point) the fine cone rule.
TERM_SETS = {"s": ("single",), "d": ("double",), "dm": ("double", "multiple"),
             "sdm": ("single", "double", "multiple")}


def model_materials(alpha: float, eta: complex, mode: str, bank_rays: Optional[int],
                    shape: str = "gaussian") -> Optional[Dict[str, pprender.Material]]:
    """The model's materials per term set; with ``orders="surface"`` on path banks of the
    autocorrelation ``shape`` (the reference cell's: each shape's banks are scored against
    surfaces of that shape); the seed's terms have no shape."""
    if mode != "surface":
        shape = "gaussian"
    key = (alpha, eta, mode, bank_rays, shape)
    if key not in _MATS:
        kw: Dict[str, Any] = dict(alpha=alpha, eta=eta, coherent_backscatter=False, orders=mode)
        if bank_rays is not None:
            kw["bank_rays"] = bank_rays
        if mode == "surface":
            kw["autocorrelation"] = shape
        try:
            _MATS[key] = {n: pprender.Material("beckmann", terms=terms, **kw) for n, terms in TERM_SETS.items()}
        except pprender.Error:  # orders="surface" outside alpha [0.05, 1]
            _MATS[key] = None
    return _MATS[key]


_VALUES: Dict[Tuple[Cell, str, Settings], Optional[Dict[str, np.ndarray]]] = {}


def model_values(cell: Cell, mode: str, s: Settings) -> Optional[Dict[str, np.ndarray]]:
    """The model's cone-averaged Mueller BRDFs ``(4, nexit, 4, 4)`` (orders 1, 2, 3+, whole)
    in the reference's bases, or None where the mode does not exist (kept per process: the
    model does not depend on the reference's tallies)."""
    key = (cell, mode, s)
    if key not in _VALUES:
        _VALUES[key] = _model_values(cell, mode, s)
    return _VALUES[key]


def _model_values(cell: Cell, mode: str, s: Settings) -> Optional[Dict[str, np.ndarray]]:
    mats = model_materials(cell.alpha, cell.eta, mode, s.bank_rays, cell.correlation)
    if mats is None:
        return None
    wi, wos = cell.wi, list(cell.wos())

    def avg(name: str, rule: Tuple[int, int]) -> np.ndarray:
        mat = mats[name]
        return ConeRule.get(wi, wos, s.cone, rule).average(lambda a, b: pprender.brdf(mat, a, b))

    s_f = avg("s", FINE) if mode == "seed" else avg("sdm", FINE) - avg("dm", FINE)
    rule = COARSE if mode == "seed" else SURFACE_RULE
    d_c, dm_c = (avg(n, rule) for n in ("d", "dm"))
    return {"m": np.stack([s_f, d_c, dm_c - d_c, s_f + dm_c])}


# ----------------------------------------------------------------------------- scoring
def verdict(miss: float, tol: float, se_allow: float) -> str:
    """"pass" (within the tolerance), "close" (a miss within 2 standard errors of the
    reference beyond it) or "fail"."""
    if not np.isfinite(miss):
        return "fail"
    if miss <= tol:
        return "pass"
    return "close" if miss <= tol + se_allow else "fail"


def score(st: Dict[str, Any], model: np.ndarray, s: Settings) -> Dict[Tuple[str, int], Dict[str, Any]]:
    """Score a model ``(4, nexit, 4, 4)`` against reference stats; returns, per (target,
    exit index) that is scored, the model's value, the miss and the verdict."""
    out: Dict[Tuple[str, int], Dict[str, Any]] = {}
    m00 = st["mean"][..., 0, 0]
    for j in range(len(EXITS)):
        ok = st["rel"][:, j] <= s.se_target
        if ok[1] and m00[1, j] > ORDER2_MIN * m00[0, j]:
            ratio = model[1, j, 0, 0] / m00[1, j]
            out[("o2_m00", j)] = {"value": ratio, "miss": abs(ratio - 1),
                                  "verdict": verdict(abs(ratio - 1), TOL["o2_m00"], 2 * st["rel"][1, j])}
            with np.errstate(invalid="ignore", divide="ignore"):
                d = np.abs(model[1, j] / model[1, j, 0, 0] - st["norm"][1, j])
            d[0, 0] = 0.0
            close = bool(np.all(d <= TOL["o2_norm"] + 2 * st["norm_se"][1, j]))
            mx = float(np.max(d))
            v = "pass" if mx <= TOL["o2_norm"] else ("close" if close else "fail")
            out[("o2_norm", j)] = {"value": mx, "miss": mx, "verdict": v if np.isfinite(mx) else "fail"}
        if ok[2]:
            ratio = model[2, j, 0, 0] / m00[2, j]
            out[("o3_m00", j)] = {"value": ratio, "miss": abs(ratio - 1),
                                  "verdict": verdict(abs(ratio - 1), TOL["o3_m00"], 2 * st["rel"][2, j])}
            dm = float(depol(model[2, j])) if model[2, j, 0, 0] > 0 else math.nan
            miss = abs(dm - st["di"][2, j])
            out[("o3_di", j)] = {"value": dm, "miss": miss,
                                 "verdict": verdict(miss, TOL["o3_di"], 2 * st["di_se"][2, j])}
        if j == 0 and ok[3]:
            dm = float(depol(model[3, j])) if model[3, j, 0, 0] > 0 else math.nan
            miss = abs(dm - st["di"][3, j])
            out[("whole_di", j)] = {"value": dm, "miss": miss,
                                    "verdict": verdict(miss, TOL["whole_di"], 2 * st["di_se"][3, j])}
    return out


# ----------------------------------------------------------------------------- run
def select(alphas: Sequence[float], thetas: Sequence[float], materials: Sequence[str],
           correlations: Sequence[str]) -> List[Cell]:
    """The cells in tracing order: alphas as given (first the most wanted, for a budgeted run),
    then materials, incidences, shapes."""
    return [Cell(c, a, m, t) for a in alphas for m in materials for t in thetas for c in correlations]


def run(cells: Sequence[Cell], s: Settings, cache: Path, *, trace: bool = True, budget_s: float = math.inf,
        log: Callable[[str], None] = print) -> Dict[str, Any]:
    """Trace (resuming from the cache) and score; returns everything the page needs."""
    t0 = time.time()
    deadline = t0 + budget_s
    rows: List[Dict[str, Any]] = []
    new_total = 0
    for cell in cells:
        if trace:
            t, new = trace_cell(cell, s, cache, deadline, log)
            new_total += new
        else:
            t = load_tally(cache, cell, s)
        rows.append({"cell": cell, "tally": t})
    t_trace = time.time() - t0
    for row in rows:
        cell = row["cell"]
        if len(row["tally"]["seeds"]) < 2:
            row["stats"] = None
            continue
        st = ref_stats(row["tally"])
        row["stats"] = st
        row["model"], row["score"] = {}, {}
        for mode in MODES:
            mv = model_values(cell, mode, s)
            row["model"][mode] = None if mv is None else mv["m"]
            row["score"][mode] = None if mv is None else score(st, mv["m"], s)
    return {"rows": rows, "new_rays": new_total, "wall_s": time.time() - t0, "trace_s": t_trace,
            "model_s": time.time() - t0 - t_trace, "settings": s}


def summary(rows: Sequence[Dict[str, Any]], by: Callable[[Cell], Any]) -> Dict[Any, Dict[Tuple[str, str], List[int]]]:
    """Per group: (target, mode) -> [scored, pass, close]."""
    out: Dict[Any, Dict[Tuple[str, str], List[int]]] = {}
    for row in rows:
        if row.get("stats") is None:
            continue
        g = out.setdefault(by(row["cell"]), {})
        for mode in MODES:
            sc = row["score"][mode]
            if sc is None:
                continue
            for (target, _), v in sc.items():
                c = g.setdefault((target, mode), [0, 0, 0])
                c[0] += 1
                c[1] += v["verdict"] == "pass"
                c[2] += v["verdict"] == "close"
    return out


# ----------------------------------------------------------------------------- page
MARK = {"pass": "✓", "close": "≈", "fail": "✗"}


def _git(path: Path, *args: str) -> str:
    try:
        out = subprocess.run(["git", "-C", str(path), *args], capture_output=True, text=True, timeout=10)
        return out.stdout.strip()
    except Exception:
        return "?"


def _rate(c: Optional[List[int]]) -> str:
    if not c or c[0] == 0:
        return "–"
    return f"{c[1]}/{c[0]} ({c[1] + c[2]})"


def summary_table(groups: Dict[Any, Dict[Tuple[str, str], List[int]]], label: str,
                  fmt: Callable[[Any], str]) -> List[str]:
    head = f"| {label} | " + " | ".join(f"{TARGET_NAMES[t]} surface | seed" for t in TOL) + " |"
    lines = [head, "|" + "---|" * (1 + 2 * len(TOL))]
    for g in sorted(groups, key=lambda x: (isinstance(x, str), x)):
        cells = [_rate(groups[g].get((t, m))) for t in TOL for m in MODES]
        lines.append(f"| {fmt(g)} | " + " | ".join(cells) + " |")
    return lines


def _pm(v: float, se: float, f: str = ".3f") -> str:
    return f"{v:{f}}±{se:{f}}" if np.isfinite(se) else f"{v:{f}}"


def _sci(v: float) -> str:
    return f"{v:.3g}"


def cell_lines(row: Dict[str, Any], s: Settings) -> List[str]:
    """Table rows of one cell, one per exit direction."""
    cell, st = row["cell"], row["stats"]
    out = []
    m = st["mean"][..., 0, 0]
    for j, (name, _, _) in enumerate(EXITS):
        def mv(mode: str, target: str, fmt: str) -> str:
            sc = row["score"][mode]
            if sc is None:
                return "n/a"
            v = sc.get((target, j))
            if v is None:
                return "–"
            return f"{v['value']:{fmt}}{MARK[v['verdict']]}"

        def refcell(o: int) -> str:
            rel = st["rel"][o, j]
            return f"{_sci(m[o, j])} ({rel:.1%})" if np.isfinite(rel) else (f"{_sci(m[o, j])} (–)")

        mod = row["model"]
        o1 = " / ".join(
            "n/a" if mod[k] is None or not m[0, j] > 0 else f"{mod[k][0, j, 0, 0] / m[0, j]:.2f}" for k in ("seed",))
        o2f = f"{m[1, j] / m[0, j]:.3g}" if m[0, j] > 0 else "–"
        di3 = _pm(st["di"][2, j], st["di_se"][2, j]) if np.isfinite(st["rel"][2, j]) else "–"
        dw = _pm(st["di"][3, j], st["di_se"][3, j]) if m[3, j] > 0 else "–"
        out.append(
            f"| {cell.correlation[:3]} | {cell.material[:2]} | {cell.theta:g} | {name} | {st['rays']:.1e} "
            f"| {refcell(0)} {o1} | {refcell(1)} | {o2f} "
            f"| {mv('surface', 'o2_m00', '.2f')} / {mv('seed', 'o2_m00', '.2f')} "
            f"| {mv('surface', 'o2_norm', '.3f')} / {mv('seed', 'o2_norm', '.3f')} "
            f"| {refcell(2)} | {mv('surface', 'o3_m00', '.2f')} / {mv('seed', 'o3_m00', '.2f')} "
            f"| {di3} | {mv('surface', 'o3_di', '.3f')} / {mv('seed', 'o3_di', '.3f')} "
            + (f"| {dw} | {mv('surface', 'whole_di', '.3f')} / {mv('seed', 'whole_di', '.3f')} |"
               if j == 0 else "| | |")
        )
    return out


def _spread(v: Sequence[float], f: str = ".2f") -> str:
    if not v:
        return "–"
    x = np.array(v)
    return f"{np.median(x):{f}} [{x.min():{f}}, {x.max():{f}}] ({len(x)})"


def spread_table(rows: Sequence[Dict[str, Any]]) -> List[str]:
    quantities = (("o2_m00", "order 2 M00 ratio", False), ("o3_m00", "3+ M00 ratio", False),
                  ("o3_di", "3+ DI difference", True), ("whole_di", "whole DI difference at bs", True))
    lines = ["| quantity | shape | surface | seed |", "|---|---|---|---|"]
    for target, name, diff in quantities:
        for corr in CORRELATIONS:
            vals: Dict[str, List[float]] = {m: [] for m in MODES}
            for r in rows:
                if r["cell"].correlation != corr:
                    continue
                for mode in MODES:
                    sc = r["score"][mode]
                    for (t, j), v in (sc or {}).items():
                        if t != target:
                            continue
                        if diff:
                            o = 2 if target == "o3_di" else 3
                            vals[mode].append(v["value"] - r["stats"]["di"][o, j])
                        else:
                            vals[mode].append(v["value"])
            f = "+.3f" if diff else ".2f"
            lines.append(f"| {name} | {corr} | {_spread(vals['surface'], f)} | {_spread(vals['seed'], f)} |")
    return lines


def shape_table(rows: Sequence[Dict[str, Any]], s: Settings) -> List[str]:
    by = {(r["cell"].correlation, r["cell"].alpha, r["cell"].material, r["cell"].theta): r["stats"] for r in rows}
    lines = ["| alpha | order 1 | order 2 | 3+ | 3+ DI difference |", "|---|---|---|---|---|"]
    for alpha in sorted({k[1] for k in by}):
        ratios: List[List[float]] = [[], [], []]
        ddi: List[float] = []
        for (corr, a, mat, th), g in by.items():
            m = by.get(("matern", a, mat, th))
            if corr != "gaussian" or a != alpha or m is None:
                continue
            for o in range(3):
                for j in range(len(EXITS)):
                    if g["rel"][o, j] <= s.se_target and m["rel"][o, j] <= s.se_target:
                        ratios[o].append(m["mean"][o, j, 0, 0] / g["mean"][o, j, 0, 0])
                        if o == 2:
                            ddi.append(m["di"][2, j] - g["di"][2, j])
        lines.append(f"| {alpha:g} | " + " | ".join(_spread(x) for x in ratios) + f" | {_spread(ddi, '+.3f')} |")
    return lines


def page(res: Dict[str, Any], argv: Sequence[str], cells_requested: Sequence[Cell]) -> str:
    s: Settings = res["settings"]
    rows = [r for r in res["rows"] if r.get("stats") is not None]
    pkg = Path(pprender.__file__).resolve().parent
    cmd = "python scripts/surface_orders_reference.py" + ("" if not argv else " " + shlex.join(argv))
    rays = sum(r["stats"]["rays"] for r in rows)
    tr = sum(r["stats"]["elapsed"] for r in rows)
    have = {(r["cell"].correlation, r["cell"].alpha, r["cell"].material, r["cell"].theta) for r in rows}
    missing = [c for c in cells_requested if (c.correlation, c.alpha, c.material, c.theta) not in have]
    w: List[str] = []
    a = w.append
    a("# Orders 1, 2, 3+ against explicit random surfaces: the scored reference (issue 24)")
    a("")
    a("Generated by `scripts/surface_orders_reference.py` (do not edit by hand). The model's Mueller BRDFs "
      '(`orders="surface"`, path banks, and `orders="seed"`, the double and multiple terms; both with '
      "`coherent_backscatter=False`) against the explicit-microsurface reference "
      "(`pprender.reference.microsurface`), incoherent, by bounce order, scored against the Targets of issue 24.")
    a("")
    a("## What was run")
    a("")
    a(f"- Command (from the repository root): `{cmd}`; this invocation took {res['wall_s']:.0f} s wall "
      f"({res['trace_s']:.0f} s tracing, {res['new_rays']:.2e} new rays; {res['model_s']:.0f} s for the model: "
      f"path banks, tables, cone averages). The reference tallies come from the cache (`--cache`), "
      f"filled by this and earlier invocations: {rays:.3e} rays in all, {tr:.0f} s of tracing "
      f"(the rays' own time, as the reference reports it).")
    a(f"- pprender {getattr(pprender, '__version__', '?')} imported from a checkout at commit "
      f"`{_git(pkg, 'rev-parse', '--short', 'HEAD')}`; {platform.machine()}, {os.cpu_count()} CPUs.")
    a(f"- Cells with data: {len(rows)} of the {len(cells_requested)} selected "
      f"({len(rows) * len(EXITS)} rows of exit directions).")
    grid_have = sorted({(r['cell'].correlation, r['cell'].material) for r in rows})
    for corr, mat in grid_have:
        al = sorted({r["cell"].alpha for r in rows if r["cell"].correlation == corr and r["cell"].material == mat})
        th = sorted({r["cell"].theta for r in rows if r["cell"].correlation == corr and r["cell"].material == mat})
        a(f"  - {corr}, {mat}: alpha {', '.join(f'{x:g}' for x in al)}; "
          f"incidence {', '.join(f'{x:g}' for x in th)} deg")
    if missing:
        a(f"- Selected but without data (the budget ran out first): {len(missing)} cells: "
          + ", ".join(c.key for c in missing[:40]) + (" ..." if len(missing) > 40 else ""))
    a("- The full grid is alpha 0.05, 0.1, 0.2, 0.3, 0.5, 0.8, 1.0; incidence 0, 30, 50, 70 deg; glass, aluminium, "
      "gold; Gaussian and Matern. To extend this page, rerun the command with more of `--alphas`, `--thetas`, "
      "`--materials`, `--correlations` (all four default to the full grid): cells already in the cache are not "
      "traced again.")
    a("")
    a("## Method")
    a("")
    a(f"- Surfaces: periodic {s.grid} x {s.grid} tiles, triangulated as the reference does. **Gaussian**: the "
      f"reference's own synthesis, C(r) = exp(-r^2/l^2), l = {CORR_LENGTH:g} cells. **Matern**: smoothness "
      f"nu = 5/2, C(r) = (1 + x + x^2/3) exp(-x), x = sqrt(5) r / L, L = {MATERN_LENGTH:.3f} cells (the same "
      "-C''(0)/C(0) as the Gaussian: the same slope rms for the same height rms), white Gaussian noise filtered "
      "by the square root of the 2-D Matern spectrum (2 nu / L^2 + k^2)^-(nu+1) with numpy's FFT and passed as "
      "`heights=`. Both are linear filters of Gaussian noise, so every slope component is exactly normal; both are "
      "rescaled so that the realized slopes of the traced triangles give alpha^2 = 2 var(slope component) exactly "
      "(checked per surface via the reference's `realized_alpha`; the synthesis is tested in "
      "`tests/test_surface_orders_reference.py`). The slope correlation differs: at r = 2 l the height "
      "correlation is 0.018 (Gaussian) against 0.10 (Matern).")
    a(f"- Materials: " + ", ".join(f"{k} eta = {v.real:g}{v.imag:+g}i" for k, v in MATERIALS.items())
      + " (the metals at 1064 nm as `pprender.materials` tabulates them: aluminium Rakic 1995, gold Johnson & "
      "Christy 1972).")
    a(f"- Exits: backscatter (bs), {EXITS[1][1]:g} and {EXITS[2][1]:g} deg bistatic in the plane of incidence toward "
      f"the normal (in15, in30; at normal incidence the plane is x-z), {EXITS[3][1]:g} deg bistatic across the plane "
      "(out30), all tallied from the same rays, in cones of half-angle "
      f"{s.cone:g} rad; the model is averaged over the same cones with the reference's weights and Stokes bases "
      "(`compare_microsurface.cone_average`; rules (6, 24) for order 1, (5, 20) beyond for `orders=\"surface\"`, "
      "(2, 8) for `\"seed\"`, which moves the seed's terms by < 0.1% where they are not negligible), so there is "
      "no cone bias.")
    a(f"- Reference runs: calls of {s.rays_per_call:.0e} rays on {s.surfaces_per_call} fresh surfaces each "
      f"(max_order {s.max_order}); standard errors from the spread of the calls (at least {s.min_calls}); normalized "
      "elements by the delta method on the calls, depolarization indices (DI) by the jackknife over calls. A cell "
      f"is traced until every row a target needs has se(M00) <= {s.se_target:.0%} of M00, leaving out rows whose "
      f"projected cost exceeds the cap of {s.max_rays:.1e} rays per cell. Seeds: {SEED_BASE:.0e} + crc32(cell) x "
      "1e5 + call: none of the path banks' (seed 1, own streams) nor of the development scripts'.")
    a("- Model: `pprender.Material(\"beckmann\", alpha, eta, coherent_backscatter=False, orders=...)`; order 1 = "
      "terms (single, double, multiple) - (double, multiple) (with `orders=\"surface\"` the single term's masking is "
      "calibrated to the bank's order 1 along with the banks; `orders=\"seed\"` has no calibration and takes "
      "terms (single,), the same sum), order 2 = (double,), 3+ = (double, multiple) - "
      "(double,), whole = (single, "
      f'double, multiple). `orders="surface"` exists for alpha in [{SURFACE_RANGE[0]:g}, {SURFACE_RANGE[1]:g}] only '
      '(n/a elsewhere), on path banks of the cell\'s own autocorrelation shape (`autocorrelation="gaussian"` or '
      '`"matern"`: each shape\'s banks are scored against surfaces of that shape, traced with other seeds)'
      + (f"; path banks of {s.bank_rays:.0e} rays per incidence node" if s.bank_rays else
         "; path banks at their default size") + ".")
    a(f"- Scoring (issue 24, Targets): a row is scored only where the reference's se(M00) <= {s.se_target:.0%} of "
      "M00 for that order. Order 2 (only where order 2 > 1% of order 1): M00 within 10%, the 15 normalized "
      "elements M_ij/M00 within 0.05. Orders 3+: M00 within 25%, DI within 0.1. Whole return at backscatter: DI "
      "within 0.03. Verdicts: ✓ pass; ≈ a miss beyond the tolerance by at most 2 reference standard errors "
      "(2 se(M00)/M00 for ratios, 2 se per element, 2 se of the DI); ✗ fail.")
    a("")
    a("## Summary: pass rates")
    a("")
    a("Entries `passes/scored (passes + within 2 se)`; – where nothing was scored (for surface: alpha outside "
      f"[{SURFACE_RANGE[0]:g}, {SURFACE_RANGE[1]:g}], or no scored row).")
    a("")
    a("### By alpha")
    a("")
    w.extend(summary_table(summary(rows, lambda c: c.alpha), "alpha", lambda g: f"{g:g}"))
    allg = summary(rows, lambda c: "all")
    label = f"alpha in [{SURFACE_RANGE[0]:g}, {SURFACE_RANGE[1]:g}]"
    rng = summary(rows, lambda c: label if SURFACE_RANGE[0] <= c.alpha <= SURFACE_RANGE[1] else None)
    rng.pop(None, None)
    w.extend(summary_table({**rng, **allg}, "alpha", str)[2:])
    a("")
    a("### By autocorrelation shape")
    a("")
    w.extend(summary_table(summary(rows, lambda c: c.correlation), "shape", str))
    a("")
    a("### By material")
    a("")
    w.extend(summary_table(summary(rows, lambda c: c.material), "material", str))
    a("")
    a("### By incidence")
    a("")
    w.extend(summary_table(summary(rows, lambda c: c.theta), "theta_i", lambda g: f"{g:g} deg"))
    a("")
    a("### Spread of model / reference over the scored rows")
    a("")
    a("M00 ratios (model / reference) and DI differences (model - reference): median [min, max] (rows).")
    a("")
    w.extend(spread_table(rows))
    a("")
    a("### The two autocorrelation shapes: Matern reference / Gaussian reference")
    a("")
    a("Same alpha, material, incidence and exit, rows where both references meet the se target: M00 "
      "ratio Matern / Gaussian per order, median [min, max] (rows); for 3+ also the DI difference Matern - "
      "Gaussian: how much the shape of the autocorrelation alone moves orders >= 2 at the same alpha, which a "
      "model on Gaussian banks would miss on a Matern surface (`orders=\"surface\"` takes "
      "`autocorrelation=\"matern\"` for those).")
    a("")
    w.extend(shape_table(rows, s))
    a("")
    a('## Failures of orders="surface"')
    a("")
    fails = []
    for r in rows:
        sc = r["score"]["surface"]
        if sc is None:
            continue
        for (target, j), v in sorted(sc.items()):
            if v["verdict"] == "fail":
                fails.append(f"{r['cell'].key} {EXITS[j][0]}: {target} {v['value']:.3f} (miss {v['miss']:.3f})")
    a(f"{len(fails)} scored rows fail beyond 2 se (rows within 2 se, ≈, are not listed)" + (":" if fails else "."))
    a("")
    for f in fails[:200]:
        a(f"- {f}")
    if len(fails) > 200:
        a(f"- ... and {len(fails) - 200} more (in the tables below)")
    a("")
    a("## Per-cell tables")
    a("")
    a("Per row: shape (gau/mat), material (gl/al/go), theta_i (deg), exit, the cell's reference rays; reference "
      "M00 (1/sr) with se/M00 per order (order 1 with seed-model/ref, the single term, not scored); order 2 / "
      "order 1 of the reference; model/ref of M00 and the largest |normalized element difference| for order 2, "
      "surface / seed; the same M00 ratio for 3+, the reference's 3+ DI ± se and the models' DI; at backscatter "
      "the whole return's DI, reference ± se and models'. ✓ ≈ ✗ as above; – not scored; n/a no such model.")
    for alpha in sorted({r["cell"].alpha for r in rows}):
        a("")
        a(f"### alpha = {alpha:g}")
        a("")
        a("| shape | mat | θi | exit | rays | order 1 ref (se), seed/ref | order 2 ref (se) | o2/o1 "
          "| o2 M00 surf / seed | o2 max Δ(M/M00) surf / seed | 3+ ref (se) | 3+ M00 surf / seed "
          "| 3+ DI ref | 3+ DI surf / seed | whole DI ref | whole DI surf / seed |")
        a("|" + "---|" * 16)
        for r in rows:
            if r["cell"].alpha == alpha:
                w.extend(cell_lines(r, s))
    a("")
    return "\n".join(w)


def parse(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    p.add_argument("--quick", action="store_true", help="small fast configuration (fewer rays, 128 grid)")
    p.add_argument("--alphas", default=",".join(f"{a:g}" for a in ALPHAS))
    p.add_argument("--thetas", default=",".join(f"{t:g}" for t in THETAS))
    p.add_argument("--materials", default=",".join(MATERIALS))
    p.add_argument("--correlations", default=",".join(CORRELATIONS))
    p.add_argument("--max-rays", type=float, default=None, help="ray cap per cell")
    p.add_argument("--se-target", type=float, default=None, help="relative se of M00 to reach and to score")
    p.add_argument("--bank-rays", type=float, default=None, help="the model's path-bank rays per incidence node")
    p.add_argument("--budget-s", type=float, default=math.inf, help="stop tracing after this many seconds")
    p.add_argument("--no-trace", action="store_true", help="score what the cache holds, trace nothing")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    return p.parse_args(list(argv))


def settings_from(args: argparse.Namespace) -> Settings:
    s = QUICK if args.quick else FULL
    if args.max_rays is not None:
        s = replace(s, max_rays=int(args.max_rays))
    if args.se_target is not None:
        s = replace(s, se_target=float(args.se_target))
    if args.bank_rays is not None:
        s = replace(s, bank_rays=int(args.bank_rays))
    return s


def main(argv: Sequence[str]) -> Dict[str, Any]:
    """Run, write the page to ``--out`` and print it; returns :func:`run`'s result with
    ``page`` (the text) added."""
    args = parse(argv)
    s = settings_from(args)
    for m in args.materials.split(","):
        if m not in MATERIALS:
            raise SystemExit(f"unknown material {m!r}: one of {', '.join(MATERIALS)}")
    for c in args.correlations.split(","):
        if c not in CORRELATIONS:
            raise SystemExit(f"unknown correlation {c!r}: one of {', '.join(CORRELATIONS)}")
    cells = select([float(x) for x in args.alphas.split(",")], [float(x) for x in args.thetas.split(",")],
                   args.materials.split(","), args.correlations.split(","))
    log = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    log(f"{len(cells)} cells, settings {asdict(s)}, cache {args.cache}")
    res = run(cells, s, args.cache, trace=not args.no_trace, budget_s=args.budget_s, log=log)
    text = page(res, argv, cells)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(text)
    res["page"] = text
    return res


if __name__ == "__main__":
    main(sys.argv[1:])
