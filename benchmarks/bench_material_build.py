"""What a material costs to build, exactly and from alpha nodes (``Material(alpha_step=h)``),
and what the nodes change, in one run; ``--write`` regenerates ``docs/material-build.md``.

For each material (the terms that need tables: multiple, double, diffuse):

- **Build time**: ``exact``, the material built at its own ``alpha`` (the median of 3);
  ``nodes, cold``: the first material in a new range of alpha (its four node materials
  built, each an exact build); ``nodes, warm``: the median over 20 further alphas within
  the same node interval (nodes kept by the process). Every row's timings come before any
  error is measured, each in a range of alpha of its own, so that no row finds nodes
  another built.
- **Error against the exact build** at 5 alphas between nodes (0.0123 to 2.3, none on a
  node; ``orders="surface"``: 4 alphas in 0.66-0.87), over 1000 random pairs of
  directions with cosines in [0.02, 1]: the largest ``|f_nodes - f_exact|`` over the 16
  Mueller elements relative to ``max(M00_exact, 0.01 /sr)`` (relative where the BRDF
  matters, absolute below 0.01 /sr: the multiple term of a smooth metal far from its lobe is 1e-25 /sr, and a relative
  error there is noise), and the largest difference of the directional albedo
  (``pprender._core.albedo``, order 128, 30 incidence angles), which is the white-furnace
  error the interpolation adds.

``python benchmarks/bench_material_build.py [--write docs/material-build.md]``
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import pprender
from pprender import _core

#: (label, Material keyword arguments); alpha is set per row.
MATERIALS = [
    ("aluminium, single + multiple", dict(distribution="beckmann", eta=1.38 + 10.2j, terms=["single", "multiple"])),
    ("aluminium, single + double + multiple",
     dict(distribution="beckmann", eta=1.38 + 10.2j, terms=["single", "double", "multiple"])),
    ("glass, single + double + multiple", dict(distribution="beckmann", eta=1.5 + 0j,
                                               terms=["single", "double", "multiple"])),
    ("white paint (GGX), single + multiple + diffuse",
     dict(distribution="ggx", eta=1.5 + 0j, terms=["single", "multiple", "diffuse"], diffuse_albedo=0.8)),
    ("aluminium, single + double + multiple, orders=\"surface\"",
     dict(distribution="beckmann", eta=1.38 + 10.2j, terms=["single", "double", "multiple"], orders="surface")),
]
ALPHAS = (0.0123, 0.137, 0.331, 0.77, 2.3)
#: orders="surface" exists for alpha in [0.05, 1] (path banks at 0.05, ..., 0.3, 0.4, ..., 1.0): its
#: rows time and measure within [0.6, 0.9], where the banks are traced first (kept on disk)
SURFACE_ALPHAS = (0.66, 0.73, 0.77, 0.87)
SURFACE_STARTS = {0.05: 0.62, 0.1: 0.83}
STEPS = (0.05, 0.1)


def _surface(kw: dict) -> bool:
    return kw.get("orders") == "surface"


def _dirs(rng: np.random.Generator, n: int) -> np.ndarray:
    th = np.arccos(rng.uniform(0.02, 1.0, n))
    ph = rng.uniform(0.0, 2.0 * np.pi, n)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)


def errors(kw: dict, step: float, n: int = 1000) -> tuple[float, float]:
    """(largest BRDF error as defined in the module docstring, largest albedo difference)
    over ALPHAS."""
    rng = np.random.default_rng(1)
    wi, wo = _dirs(rng, n), _dirs(rng, n)
    cos = np.linspace(0.01, 1.0, 30)
    e_f, e_a = 0.0, 0.0
    for a in SURFACE_ALPHAS if _surface(kw) else ALPHAS:
        ex = pprender.Material(alpha=a, **kw)
        ip = pprender.Material(alpha=a, alpha_step=step, **kw)
        fe, fi = _core.brdf(ex, wi, wo, "sp"), _core.brdf(ip, wi, wo, "sp")
        e_f = max(e_f, float((np.abs(fi - fe).max(axis=(1, 2)) / np.maximum(fe[:, 0, 0], 1e-2)).max()))
        e_a = max(e_a, float(np.abs(_core.albedo(ip, cos, 128) - _core.albedo(ex, cos, 128)).max()))
    return e_f, e_a


def build_times(kw: dict, step: float, start: float) -> tuple[float, float, float]:
    """(exact, nodes cold, nodes warm) seconds at alphas from ``start`` (a range of alpha
    no earlier row used, so that its nodes are cold)."""
    def t(**k: object) -> float:
        t0 = time.perf_counter()
        pprender.Material(**kw, **k)  # type: ignore[arg-type]
        return time.perf_counter() - t0

    exact = float(np.median([t(alpha=start) for _ in range(3)]))
    cold = t(alpha=start, alpha_step=step)
    u0 = np.log(start) / step
    lo = np.floor(u0)
    warm = [t(alpha=float(np.exp(step * (lo + f))), alpha_step=step) for f in np.linspace(0.05, 0.95, 20)]
    return exact, cold, float(np.median(warm))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", default=None, help="write the markdown page here")
    a = ap.parse_args(argv)
    t_start = time.perf_counter()
    cases = [(label, kw, step) for label, kw in MATERIALS for step in STEPS]
    times = []
    for kw in {id(kw): kw for _, kw, _ in cases if _surface(kw)}.values():
        for alpha in (0.65, 0.75, 0.85):  # the path banks 0.6-0.9 traced (or read) before any timing
            pprender.Material(alpha=alpha, **kw)
    for k, (label, kw, step) in enumerate(cases):
        # start alphas 1.7x apart (four nodes span 1.35x at step 0.1), so no row finds
        # another's nodes; all timings before the errors, whose materials build nodes too
        start = SURFACE_STARTS[step] if _surface(kw) else 0.031 * 1.7**k
        times.append(build_times(kw, step, start))
        print(f"{label:48s} step {step:4.2f}: exact {times[-1][0]*1e3:7.1f} ms, nodes cold "
              f"{times[-1][1]*1e3:7.1f} ms, warm {times[-1][2]*1e3:6.1f} ms", flush=True)
    rows = []
    for (label, kw, step), t in zip(cases, times):
        e_f, e_a = errors(kw, step)
        rows.append((label, step, *t, e_f, e_a))
        print(f"{label:48s} step {step:4.2f}: BRDF error {e_f:.1e}, albedo error {e_a:.1e}", flush=True)
    lines = [
        "# Material build: exact and from alpha nodes",
        "",
        "Written by `python benchmarks/bench_material_build.py --write docs/material-build.md` "
        "(its docstring defines every column); "
        f"{os.cpu_count()} CPU threads ({platform.machine()}), pprender {pprender.__version__}, "
        f"{time.perf_counter() - t_start:.0f} s.",
        "",
        "`Material(..., alpha_step=h)` interpolates the tables that normalize the multiple, diffuse and "
        "double terms (albedos, escape after a bounce) in `ln alpha` from the materials at the nodes "
        "`exp(j h)`, kept by the process; the single term is exact. Interpolated in `ln(1 - value)`, "
        "so that deficits that go as powers of alpha are followed. Build time with the default "
        "orders (`\"seed\"`), except the last rows: with `orders=\"surface\"` the banks' orders are "
        "mixed at alpha itself (the banks' node tables built once per process, the banks on disk "
        "already: traced before the timings) and the nodes, within the banks' alpha interval that "
        "holds alpha, give the single term's calibration to the traced surface; its errors at alpha "
        f"{', '.join(str(a) for a in SURFACE_ALPHAS)}.",
        "",
        "| material | alpha_step | exact (ms) | nodes, cold (ms) | nodes, warm (ms) | BRDF error | albedo error |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, step, ex, cold, warm, e_f, e_a in rows:
        lines.append(f"| {label} | {step:g} | {ex*1e3:.1f} | {cold*1e3:.1f} | {warm*1e3:.1f} | {e_f:.1e} | {e_a:.1e} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.write:
        with open(a.write, "w") as f:
            f.write(text)
        print(f"wrote {a.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
