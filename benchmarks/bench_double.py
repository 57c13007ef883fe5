"""Double-bounce cost against accuracy: evaluations per second and error against the
quadrature order, and the build time of the monostatic double-bounce tables.

Run ``python benchmarks/bench_double.py`` (``--write`` also writes
``docs/double-bounce-benchmark.md``), or call :func:`main`.

What is measured, in one process:

* **Order sweep** (one table). For three materials (Beckmann alpha 0.5 metal, Blinn-Phong
  m = 10 dielectric, GGX alpha 0.3 metal) and the orders 16 ... 192, the double term alone
  (``terms=("double",)``, ``double_order=N``, coherent backscatter as by default):

  - throughput: ``brdf`` on random direction pairs uniform in solid angle (seeded, as in
    ``benchmarks/bench.py``), best and median of ``repeats`` runs, the first call excluded. The
    binding runs on one thread below 2048 pairs and a double-bounce evaluation costs
    milliseconds, so each timed call holds 2048 pairs: ``k`` random pairs (``k`` chosen so
    that a call takes about ``target_time``; all 2048 at low orders) spread evenly among
    pairs on the horizon, which return the zero matrix without evaluating the model (about
    0.1 us each, negligible). evals/s = k / best time.
  - error: against order 384 on a fixed seeded set of 200 pairs (uniform, exact and near
    backscatter, specular, near-grazing; see :func:`error_pairs`). Per pair
    ``max_ij |M_ij(N) - M_ij(384)| / M00(384)``, over the pairs where the double term is
    significant: ``M00_double(384) >= 1e-3 M00_total`` with ``M00_total`` the full BRDF
    (``terms=("single", "double", "multiple")``, default order). Max and median reported.

* **Monostatic tables**: ``_core.monostatic_table(material, nodes=64, double_order=48 or
  32)`` for the full material (single + double + multiple, default order) of five
  materials: one call with ``measure=True`` for the table's max error (the tabulated
  double term at the node midpoints against the material's own evaluation, relative to
  the total monostatic M00), then ``repeats`` calls with ``measure=False`` timed (wall
  clock of the call; best and median).

Targets (the issue): the default order at 1e-4 relative error; a monostatic table of one
material in under 0.1 s.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import pprender
from pprender import _core
from bench import cpu_model, emit_report, load_average, threads_available, timed, uniform_hemisphere

SEED = 2024
ORDERS = (16, 24, 32, 48, 64, 96, 128, 160, 192)
REF_ORDER = 384
SIGNIFICANT = 1e-3  # M00_double >= SIGNIFICANT * M00_total
ERROR_TARGET = 1e-4
TABLE_TARGET = 0.1  # s
PAR_MIN = 2048  # the binding's parallel threshold (src/python/brdf.rs)
TABLE_NODES = 64
TABLE_ORDERS = (48, 32)

SWEEP_MATERIALS: list[tuple[str, dict[str, Any]]] = [
    ("Beckmann a=0.5, eta 0.2+3.4i", dict(distribution="beckmann", alpha=0.5, eta=0.2 + 3.4j)),
    ("Blinn-Phong m=10, eta 1.5", dict(distribution="blinn_phong", m=10.0, eta=1.5 + 0j)),
    ("GGX a=0.3, eta 0.2+3.4i", dict(distribution="ggx", alpha=0.3, eta=0.2 + 3.4j)),
]
TABLE_MATERIALS: list[tuple[str, dict[str, Any]]] = SWEEP_MATERIALS + [
    ("Beckmann a=0.1, eta 0.2+3.4i", dict(distribution="beckmann", alpha=0.1, eta=0.2 + 3.4j)),
    ("GGX a=0.1, eta 0.2+3.4i", dict(distribution="ggx", alpha=0.1, eta=0.2 + 3.4j)),
]
FULL_TERMS = ("single", "double", "multiple")


# --------------------------------------------------------------------------------------
# Direction pairs
# --------------------------------------------------------------------------------------


def _dir(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def _theta_cos_uniform(rng: np.random.Generator, n: int, lo_deg: float, hi_deg: float) -> np.ndarray:
    """Polar angles with cos(theta) uniform between the two limits."""
    c = rng.uniform(np.cos(np.radians(hi_deg)), np.cos(np.radians(lo_deg)), n)
    return np.arccos(c)


def _mirror(w: np.ndarray) -> np.ndarray:
    out: np.ndarray = w * np.array([-1.0, -1.0, 1.0])
    return out


def error_pairs(seed: int = SEED) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The fixed set of 200 (wi, wo) pairs for the error: 100 uniform in solid angle, 30
    exact backscatter (theta 0-85 deg), 20 near backscatter (0.1-5 deg off, log-uniform,
    theta_i 0-80 deg), 20 specular (theta 0-85 deg) and 30 near-grazing (theta_i 80-89.5
    deg: 10 backscatter, 10 specular, 10 with wo also at 80-89.5 deg, random azimuth)."""
    rng = np.random.default_rng(seed)
    wi_l, wo_l, cls = [], [], []

    def add(a: np.ndarray, b: np.ndarray, name: str) -> None:
        wi_l.append(a)
        wo_l.append(b)
        cls.extend([name] * len(a))

    add(uniform_hemisphere(rng, 100), uniform_hemisphere(rng, 100), "uniform")
    w = _dir(_theta_cos_uniform(rng, 30, 0.0, 85.0), rng.uniform(0, 2 * np.pi, 30))
    add(w, w.copy(), "backscatter")
    # near backscatter: rotate wi by delta about a random axis normal to it
    w = _dir(_theta_cos_uniform(rng, 20, 0.0, 80.0), rng.uniform(0, 2 * np.pi, 20))
    delta = np.radians(10 ** rng.uniform(np.log10(0.1), np.log10(5.0), 20))
    psi = rng.uniform(0, 2 * np.pi, 20)
    e1 = np.cross(w, [0.0, 0.0, 1.0])
    small = np.linalg.norm(e1, axis=-1) < 1e-9
    e1[small] = [1.0, 0.0, 0.0]
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(w, e1)
    wo = np.cos(delta)[:, None] * w + np.sin(delta)[:, None] * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    wo[:, 2] = np.abs(wo[:, 2])
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    add(w, wo, "near backscatter")
    w = _dir(_theta_cos_uniform(rng, 20, 0.0, 85.0), rng.uniform(0, 2 * np.pi, 20))
    add(w, _mirror(w), "specular")
    tg = np.radians(rng.uniform(80.0, 89.5, 30))
    w = _dir(tg, rng.uniform(0, 2 * np.pi, 30))
    add(w[:10], w[:10].copy(), "grazing")
    add(w[10:20], _mirror(w[10:20]), "grazing")
    wo = _dir(np.radians(rng.uniform(80.0, 89.5, 10)), rng.uniform(0, 2 * np.pi, 10))
    add(w[20:], wo, "grazing")
    return np.concatenate(wi_l), np.concatenate(wo_l), cls


def brdf_parallel(mat: pprender.Material, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """``pprender.brdf`` on both cores for fewer than 2048 pairs: the pairs are spread
    evenly among horizon pairs (zero matrix, not evaluated) up to 2048."""
    k = len(wi)
    if k >= PAR_MIN:
        return pprender.brdf(mat, wi, wo)
    idx = np.linspace(0, PAR_MIN - 1, k).round().astype(int)
    a = np.tile([1.0, 0.0, 0.0], (PAR_MIN, 1))
    b = a.copy()
    a[idx] = wi
    b[idx] = wo
    out: np.ndarray = pprender.brdf(mat, a, b)[idx]
    return out


# --------------------------------------------------------------------------------------
# Measurements
# --------------------------------------------------------------------------------------


@dataclass
class OrderResult:
    order: int
    k: int = 0
    times: list[float] = field(default_factory=list)
    first: float = 0.0
    errors: np.ndarray | None = None  # per significant pair

    @property
    def rate(self) -> float:
        return self.k / min(self.times)

    @property
    def rate_median(self) -> float:
        return self.k / statistics.median(self.times)


@dataclass
class SweepResult:
    label: str
    default_order: int
    orders: list[OrderResult]
    n_pairs: int
    n_significant: int
    classes: list[str]  # of the significant pairs
    geometry: np.ndarray  # (n_significant, 4): theta_i, theta_o, phi_o - phi_i (deg), M00_d / M00_total
    t_reference: float
    t_errors: float
    t_throughput: float
    nonfinite: int = 0


def _geometry(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    ti = np.degrees(np.arccos(np.clip(wi[:, 2], -1, 1)))
    to = np.degrees(np.arccos(np.clip(wo[:, 2], -1, 1)))
    dphi = np.degrees(np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0]))
    dphi = (dphi + 180.0) % 360.0 - 180.0
    return np.stack([ti, to, dphi], axis=-1)


def full_material(kw: dict[str, Any], cache: dict[str, tuple[pprender.Material, float]] | None = None,
                  ) -> tuple[pprender.Material, float]:
    """The full material (single + double + multiple, default order) and its construction
    time, built once per parameter set."""
    key = repr(sorted(kw.items()))
    if cache is not None and key in cache:
        return cache[key]
    t0 = time.perf_counter()
    mat = pprender.Material(**kw, terms=FULL_TERMS)
    out = (mat, time.perf_counter() - t0)
    if cache is not None:
        cache[key] = out
    return out


def sweep(label: str, kw: dict[str, Any], repeats: int, target_time: float, seed: int,
          log: Any, cache: dict[str, tuple[pprender.Material, float]] | None = None) -> SweepResult:
    default_order = pprender.Material(**kw).double_order
    wi, wo, cls = error_pairs(seed)

    # Reference and significance.
    t0 = time.perf_counter()
    ref_mat = pprender.Material(**kw, terms=("double",), double_order=REF_ORDER)
    ref = brdf_parallel(ref_mat, wi, wo)
    total = brdf_parallel(full_material(kw, cache)[0], wi, wo)[:, 0, 0]
    t_ref = time.perf_counter() - t0
    d00 = ref[:, 0, 0]
    sig = (d00 > 0) & (d00 >= SIGNIFICANT * total) & np.isfinite(d00)
    log(f"  {label}: reference order {REF_ORDER} on {len(wi)} pairs in {t_ref:.1f} s, "
        f"{int(sig.sum())} significant")

    results = [OrderResult(o) for o in ORDERS]
    # Errors.
    t0 = time.perf_counter()
    nonfinite = 0
    for r in results:
        mat = pprender.Material(**kw, terms=("double",), double_order=r.order)
        got = brdf_parallel(mat, wi, wo)
        err = np.abs(got - ref).reshape(len(wi), 16).max(axis=1) / np.where(d00 > 0, d00, 1.0)
        nonfinite += int((~np.isfinite(err[sig])).sum())
        r.errors = err[sig]
    t_err = time.perf_counter() - t0

    # Throughput.
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed + 1)
    twi, two = uniform_hemisphere(rng, PAR_MIN), uniform_hemisphere(rng, PAR_MIN)
    k0 = 16
    for r in results:
        mat = pprender.Material(**kw, terms=("double",), double_order=r.order)
        r.first = timed(lambda: brdf_parallel(mat, twi[:k0], two[:k0]))  # one-off + calibration
        k = int(round(target_time * k0 / max(r.first, 1e-9)))
        r.k = k = int(min(PAR_MIN, max(k0, k)))
        a, b = twi[:k], two[:k]
        for _ in range(repeats):
            r.times.append(timed(lambda: brdf_parallel(mat, a, b)))
    t_thr = time.perf_counter() - t0
    log(f"  {label}: errors {t_err:.1f} s, throughput {t_thr:.1f} s")

    geo = np.concatenate([_geometry(wi, wo), (d00 / np.where(total > 0, total, 1.0))[:, None]], axis=1)
    return SweepResult(label, default_order, results, len(wi), int(sig.sum()),
                       [c for c, s in zip(cls, sig) if s], geo[sig], t_ref, t_err, t_thr, nonfinite)


@dataclass
class TableResult:
    label: str
    order: int
    times: list[float]
    internal: list[float]
    max_error: float
    t_material: float
    node_error: float  # the table's nodes (order N, exact there) against the default order


def _node_error(mat: pprender.Material, kw: dict[str, Any], theta: np.ndarray, vals: np.ndarray) -> float:
    """Max over the table's nodes of max_ij |table - double term at the default order| / total
    M00 (backscatter, sp frame): the part of the table error that the lower order causes
    (interpolation is exact at the nodes)."""
    w = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=-1)
    ok = w[:, 2] > 0
    w = w[ok]
    want = brdf_parallel(pprender.Material(**kw, terms=("double",)), w, w)
    total = brdf_parallel(mat, w, w)[:, 0, 0]
    e = np.abs(vals[ok] - want).reshape(len(w), 16).max(axis=1)
    return float(np.max(np.where(total > 0, e / np.where(total > 0, total, 1.0), 0.0)))


def tables(repeats: int, log: Any, cache: dict[str, tuple[pprender.Material, float]] | None = None,
           ) -> list[TableResult]:
    out = []
    for label, kw in TABLE_MATERIALS:
        mat, t_mat = full_material(kw, cache)
        for order in TABLE_ORDERS:
            theta, vals, _, err = _core.monostatic_table(mat, nodes=TABLE_NODES, double_order=order, measure=True)
            node_err = _node_error(mat, kw, theta, vals)
            times, internal = [], []
            for _ in range(repeats):
                t0 = time.perf_counter()
                _, _, secs, _ = _core.monostatic_table(mat, nodes=TABLE_NODES, double_order=order, measure=False)
                times.append(time.perf_counter() - t0)
                internal.append(secs)
            out.append(TableResult(label, order, times, internal, float(err if err is not None else np.nan), t_mat,
                                   node_err))
        log(f"  table {label}: done")
    return out


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------


def _rate(r: float) -> str:
    return f"{r / 1e3:.1f} k/s" if r >= 1e4 else f"{r:,.0f} /s"


def _err(e: float) -> str:
    return f"{e:.1e}" if np.isfinite(e) else "n/a"


def _ms(t: float) -> str:
    return f"{t * 1e3:.0f} ms" if t >= 0.01 else f"{t * 1e3:.1f} ms"


def _first_order_below(s: SweepResult, tol: float) -> int | None:
    """The lowest order from which on every higher measured order meets tol."""
    best = None
    for r in reversed(s.orders):
        assert r.errors is not None
        if r.errors.size and r.errors.max() <= tol:
            best = r.order
        else:
            break
    return best


def render(sweeps: list[SweepResult], tabs: list[TableResult], info: dict[str, Any]) -> str:
    L: list[str] = ["# Double-bounce benchmark: cost and accuracy against the quadrature order", ""]
    L.append(
        f"`python benchmarks/bench_double.py` (best and median of {info['repeats']} runs; one-off costs excluded). "
        "The double term alone (`terms=(\"double\",)`, coherent backscatter on, the default), in the sp frame. "
        "The method, pair set and error definition are in the module docstring "
        "(`python/pprender/bench_double.py`)."
    )
    L.append("")
    L.append(f"- Machine: {info['cpu']}, {info['threads']} threads available "
             f"(pprender/rayon: {info['rayon_threads']}); load average at start {info['load_start']}, "
             f"at end {info['load_end']}; total run time {info['wall']:.0f} s.")
    L.append(f"- Software: pprender {pprender.__version__} (float64), numpy {np.__version__}, "
             f"Python {platform.python_version()}.")
    L.append("")

    # ---- Table 1
    L.append("## Evaluations per second and error against the order")
    L.append("")
    L.append(
        f"Throughput: random pairs uniform in solid angle, each call on 2048 pairs (k random ones "
        f"among horizon pairs at high orders, so that both cores work), evals/s = k / best time. "
        f"Error: max and median over the significant pairs of a fixed set of "
        f"{sweeps[0].n_pairs} (seed {info['seed']}) of max_ij |dM_ij| / M00_double against order {REF_ORDER}; "
        f"significant: M00_double >= {SIGNIFICANT:g} M00_total. **Bold**: the default order."
    )
    L.append("")
    head = "| order |" + "".join(f" {s.label}: evals/s | max err | median err |" for s in sweeps)
    L.append(head)
    L.append("| ---: |" + " ---: | ---: | ---: |" * len(sweeps))
    for i, o in enumerate(ORDERS):
        cells = []
        is_default = {s.default_order for s in sweeps} == {o}
        for s in sweeps:
            r = s.orders[i]
            assert r.errors is not None
            mx = r.errors.max() if r.errors.size else float("nan")
            md = float(np.median(r.errors)) if r.errors.size else float("nan")
            cells.append(f" {_rate(r.rate)} | {_err(mx)} | {_err(md)} |")
        name = f"**{o} (default)**" if is_default else str(o)
        L.append(f"| {name} |" + "".join(cells))
    L.append("")
    L.append("Significant pairs per material: " + "; ".join(
        f"{s.label}: {s.n_significant} of {s.n_pairs}" for s in sweeps) + ".")
    L.append("Median throughput (k / median time) and the number k of random pairs per call: " + "; ".join(
        f"{s.label}: " + ", ".join(f"{r.order}: {_rate(r.rate_median)} (k={r.k})" for r in s.orders) for s in sweeps) + ".")
    nf = sum(s.nonfinite for s in sweeps)
    if nf:
        L.append(f"Non-finite errors: {nf} (counted as failures).")
    L.append("")

    # Where the error sits, at the default order.
    L.append("Largest error by pair class at the default order, and the worst pair "
             "(theta_i, theta_o, phi_o - phi_i in degrees; M00_double / M00_total):")
    L.append("")
    for s in sweeps:
        r = next(x for x in s.orders if x.order == s.default_order)
        assert r.errors is not None
        by: dict[str, float] = {}
        for c, e in zip(s.classes, r.errors):
            by[c] = max(by.get(c, 0.0), float(e))
        j = int(np.argmax(r.errors))
        g = s.geometry[j]
        parts = ", ".join(f"{c} {_err(e)}" for c, e in by.items())
        L.append(f"- {s.label}: {parts}. Worst: {s.classes[j]} ({g[0]:.1f}, {g[1]:.1f}, {g[2]:.1f}); "
                 f"M00_double / M00_total = {g[3]:.2g}.")
    L.append("")

    # ---- Table 2
    L.append("## Monostatic double-bounce table build")
    L.append("")
    L.append(
        f"`_core.monostatic_table(material, nodes={TABLE_NODES}, double_order=N)` of the full material "
        f"(`terms={FULL_TERMS}`, default order). Build time: wall clock of a `measure=False` call, best and "
        f"median of {info['repeats']} (the Rust-side build time in brackets); max error: one `measure=True` call "
        "(the tabulated double term at the node midpoints against the material's own evaluation at its default "
        "order, relative to the total monostatic M00: interpolation and the lower order together). "
        "At the nodes: the same error measured at the table's own nodes, where the interpolation is exact "
        "(the lower order's share). Material construction (energy tables, once per material) listed for scale."
    )
    L.append("")
    L.append("| material | double_order | build (best) | build (median) | max error | at the nodes | < 0.1 s "
             "| material construction |")
    L.append("| --- | ---: | ---: | ---: | ---: | ---: | :---: | ---: |")
    for t in tabs:
        ok = "yes" if min(t.times) < TABLE_TARGET else "**no**"
        L.append(f"| {t.label} | {t.order} | {_ms(min(t.times))} ({_ms(min(t.internal))}) | "
                 f"{_ms(statistics.median(t.times))} | {_err(t.max_error)} | {_err(t.node_error)} | {ok} | "
                 f"{_ms(t.t_material)} |")
    L.append("")

    # ---- Verdicts
    L.append("## Targets")
    L.append("")
    L.append(f"Default order at {ERROR_TARGET:g} relative error (max over the significant pairs):")
    L.append("")
    for s in sweeps:
        r = next(x for x in s.orders if x.order == s.default_order)
        assert r.errors is not None
        mx = float(r.errors.max()) if r.errors.size else float("nan")
        frac = float(np.mean(r.errors <= ERROR_TARGET)) if r.errors.size else float("nan")
        first = _first_order_below(s, ERROR_TARGET)
        r192 = s.orders[-1]
        assert r192.errors is not None
        mx192 = float(r192.errors.max())
        verdict = "**met**" if mx <= ERROR_TARGET else "**NOT met**"
        line = (f"- {s.label}: {verdict} at order {s.default_order}: max {_err(mx)}, "
                f"median {_err(float(np.median(r.errors)))}, {100 * frac:.0f}% of the pairs within {ERROR_TARGET:g}; ")
        tmax = np.maximum(s.geometry[:, 0], s.geometry[:, 1])
        fail = r.errors > ERROR_TARGET
        if fail.any():
            lim = float(tmax[fail].min())
            line += (f"all pairs with theta_i, theta_o < {lim:.1f} deg are within it "
                     f"({int((tmax < lim).sum())} of {len(tmax)}); ")
        rel_total = r.errors * s.geometry[:, 3]
        line += f"relative to the total BRDF M00 the max is {_err(float(rel_total.max()))}; "
        if first is not None:
            line += f"every order from {first} on meets it."
        else:
            line += (f"no measured order meets it (order {ORDERS[-1]}: max {_err(mx192)}; that is also an estimate "
                     f"of how far order {REF_ORDER} itself may be off).")
        L.append(line)
    L.append("")
    L.append(f"Monostatic table in under {TABLE_TARGET:g} s (best wall time):")
    L.append("")
    for label, _ in TABLE_MATERIALS:
        rows = [t for t in tabs if t.label == label]
        parts = "; ".join(
            f"order {t.order}: {_ms(min(t.times))} ({'met' if min(t.times) < TABLE_TARGET else 'NOT met'}), "
            f"max error {_err(t.max_error)}" for t in rows)
        L.append(f"- {label}: {parts}.")
    L.append("")
    L.append("Run costs: " + "; ".join(
        f"{s.label}: reference {s.t_reference:.0f} s, error sweep {s.t_errors:.0f} s, throughput {s.t_throughput:.0f} s"
        for s in sweeps) + f"; tables {info['t_tables']:.0f} s.")
    L.append("")
    return "\n".join(L) + "\n"


# --------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------


def main(repeats: int = 3, target_time: float = 0.15, seed: int = SEED,
         write: bool | str | os.PathLike[str] = False, quiet: bool = False) -> str:
    """Run the benchmark, print the markdown report and return it. ``write=True`` writes
    ``docs/double-bounce-benchmark.md`` of the source tree (or of the working directory)."""
    if repeats < 1 or target_time <= 0:
        raise ValueError("repeats and target_time must be positive")
    t_start = time.perf_counter()
    info: dict[str, Any] = {
        "cpu": cpu_model(),
        "threads": threads_available(),
        "rayon_threads": os.environ.get("RAYON_NUM_THREADS", str(threads_available())),
        "load_start": load_average(),
        "repeats": repeats,
        "seed": seed,
    }

    def log(msg: str) -> None:
        if not quiet:
            print(f"[{time.perf_counter() - t_start:6.1f} s]{msg}", flush=True)

    cache: dict[str, tuple[pprender.Material, float]] = {}
    sweeps = [sweep(label, kw, repeats, target_time, seed, log, cache) for label, kw in SWEEP_MATERIALS]
    t0 = time.perf_counter()
    tabs = tables(repeats, log, cache)
    info["t_tables"] = time.perf_counter() - t0
    info["load_end"] = load_average()
    info["wall"] = time.perf_counter() - t_start
    report = render(sweeps, tabs, info)
    return emit_report(report, write, "double-bounce-benchmark.md", quiet)


def _cli(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python benchmarks/bench_double.py", description=__doc__.splitlines()[0])
    p.add_argument("-r", "--repeats", type=int, default=3, help="timed repetitions (default 3)")
    p.add_argument("-t", "--target-time", type=float, default=0.15,
                   help="seconds per timed throughput call (sets k; default 0.15)")
    p.add_argument("--seed", type=int, default=SEED, help=f"seed of the pair set (default {SEED})")
    p.add_argument("--write", nargs="?", const=True, default=False, metavar="PATH",
                   help="also write the report (default docs/double-bounce-benchmark.md)")
    a = p.parse_args(argv)
    main(repeats=a.repeats, target_time=a.target_time, seed=a.seed, write=a.write)


if __name__ == "__main__":
    _cli()
