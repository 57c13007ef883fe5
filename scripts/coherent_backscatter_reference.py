#!/usr/bin/env python3
"""Coherent backscatter of ``orders="surface"`` against the explicit microsurface's coherent
tally (issue 24, item 3): the enhancement at exact backscatter, element by element, for
order 2 and orders 3+, and the half width of the peak in and across the plane of
incidence. Writes docs/coherent-backscatter.md and prints it.

    python scripts/coherent_backscatter_reference.py [--alphas 0.5,0.8,1] [--thetas 0,30,50]
        [--materials glass,aluminium,gold] [--rays N] [--cache DIR] [--out FILE]

Reference: ``pprender.reference.microsurface`` with its coherent tally (each escaping path
of order >= 2 summed in amplitude with its traced reverse, phase ``q . rho`` with the full
3D separation), Gaussian surfaces (256 x 256 cells, correlation length 8 cells), cone 0.1
rad about backscatter, wavelength 1 cell (so l / lambda = 8), bistatic angles 0 to 0.1 rad.
Seeds ``8e15 + crc32(cell) * 1000``: none of the path banks' (seed 1, streams of their own).

Model: ``pprender.Material("beckmann", alpha, eta, orders="surface", wavelength=1e-6,
correlation_length=8e-6)`` (the same l / lambda), default path banks: the coherent part is
(coherent_backscatter on) - (off); order 2 from ``terms=("double",)``, orders 3+ from
``("double", "multiple")`` minus order 2.

Each cell's reference tally is saved in ``--cache`` (one file per cell and ray count), so
a rerun traces only what is missing.
"""

from __future__ import annotations

import argparse
import math
import platform
import shlex
import subprocess
import sys
import time
import zlib
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

import pprender
from pprender import reference

ALPHAS = (0.5, 0.8, 1.0)
THETAS = (0.0, 30.0, 50.0)
MATERIALS: Dict[str, complex] = {
    "glass": 1.5 + 0j,
    "aluminium": 1.3763 + 10.2449j,  # Rakic 1995, as pprender.materials tabulates it at 1064 nm
    "gold": 0.2585 + 6.9654j,  # Johnson & Christy 1972, likewise
}
GRID = 256
CORR_LENGTH = 8.0  # cells
WAVELENGTH = 1.0  # cells
CONE = 0.1
BETAS = np.linspace(0.0, 0.1, 26)
AZIMUTHS = (("in+", 0.0), ("in-", math.pi), ("out", math.pi / 2))
SEED_BASE = 8_000_000_000_000_000
TOL_R = 0.05  # enhancement per element, in units of the order's incoherent M00
TOL_W = 0.20  # half width, relative
SE_SCORE = 0.05  # a (cell, order) is scored where the reference's peak (largest |R_ii|) has se <= 5%
DEFAULT_CACHE = Path.home() / ".cache" / "pprender" / "coherent-backscatter-reference"
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "docs" / "coherent-backscatter.md"
ORDERS = ("2", "3+")


def directions(theta_deg: float) -> Tuple[np.ndarray, np.ndarray]:
    t = math.radians(theta_deg)
    wi = np.array([math.sin(t), 0.0, math.cos(t)])
    bist = np.concatenate([reference.bistatic_directions(wi, BETAS, az) for _, az in AZIMUTHS])
    return wi, bist


def trace(alpha: float, theta: float, material: str, rays: int, cache: Path) -> Dict[str, np.ndarray]:
    name = f"a{alpha:g}-t{theta:g}-{material}-r{rays}-b{len(BETAS)}x{len(AZIMUTHS)}"
    path = cache / f"{name}.npz"
    if path.exists():
        try:
            with np.load(path) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError):
            pass
    wi, bist = directions(theta)
    t0 = time.perf_counter()
    out = reference.microsurface(
        wi, wi[None, :], alpha=alpha, eta=MATERIALS[material], rays=rays, batches=16, cone=CONE,
        correlation_length=CORR_LENGTH, grid=GRID, wavelength=WAVELENGTH, bistatic=bist,
        seed=SEED_BASE + zlib.crc32(name.encode()) * 1000)
    res = {
        "mueller": out["mueller"][:, 0],
        "mueller_stderr": out["stderr"][:, 0],
        "unpaired": out["coherent_unpaired"],
        "coherent": out["coherent"],
        "coherent_stderr": out["coherent_stderr"],
        "seconds": np.array(time.perf_counter() - t0),
    }
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{np.random.default_rng().integers(1 << 30)}.npz")
    np.savez(tmp, **res)
    tmp.replace(path)
    return res


def model(alpha: float, theta: float, material: str) -> Dict[str, np.ndarray]:
    """Coherent parts (2, B, 4, 4) along the bistatic directions and incoherent parts (2, 4, 4)
    at backscatter, orders 2 and 3+."""
    wi, bist = directions(theta)
    kw = dict(alpha=alpha, eta=MATERIALS[material], orders="surface", wavelength=1e-6,
              correlation_length=CORR_LENGTH * 1e-6)

    def mat(terms: Tuple[str, ...], cbe: bool) -> pprender.Material:
        return pprender.Material("beckmann", terms=terms, coherent_backscatter=cbe, **kw)

    d = {c: mat(("double",), c) for c in (True, False)}
    dm = {c: mat(("double", "multiple"), c) for c in (True, False)}
    wis = np.repeat(wi[None], len(bist), 0)
    c2 = pprender.brdf(d[True], wis, bist) - pprender.brdf(d[False], wis, bist)
    c23 = pprender.brdf(dm[True], wis, bist) - pprender.brdf(dm[False], wis, bist)
    i2 = pprender.brdf(d[False], wi, wi)
    i3 = pprender.brdf(dm[False], wi, wi) - i2
    return {"coherent": np.stack([c2, c23 - c2]), "incoherent": np.stack([i2, i3])}


def half_width(y: np.ndarray, se: Optional[np.ndarray] = None) -> Tuple[float, float]:
    """Half width at half maximum of ``y`` along BETAS (linear interpolation of the first
    crossing of y[0] / 2), and its standard error by the delta method from ``se``."""
    if not y[0] > 0:
        return math.nan, math.nan
    r = y / y[0]
    below = np.nonzero(r < 0.5)[0]
    if len(below) == 0 or below[0] == 0:
        return math.nan, math.nan
    i = below[0]
    hw = BETAS[i - 1] + (r[i - 1] - 0.5) / (r[i - 1] - r[i]) * (BETAS[i] - BETAS[i - 1])
    if se is None:
        return float(hw), 0.0
    slope = (r[i] - r[i - 1]) / (BETAS[i] - BETAS[i - 1])
    s_r = math.hypot(se[i - 1], 0.5 * se[0]) / y[0]
    return float(hw), float(s_r / abs(slope)) if slope != 0 else math.inf


def verdict(miss: float, tol: float, se: float) -> str:
    if not math.isfinite(miss):
        return "–"
    if miss <= tol:
        return "✓"
    return "≈" if miss <= tol + 2 * se else "✗"


def score_cell(alpha: float, theta: float, material: str, rays: int, cache: Path) -> List[Dict[str, Any]]:
    ref = trace(alpha, theta, material, rays, cache)
    mod = model(alpha, theta, material)
    nb = len(BETAS)
    inc = [ref["mueller"][1], ref["mueller"][2:].sum(0)]
    rows = []
    for o, oname in enumerate(ORDERS):
        i00 = inc[o][0, 0]
        c_ref = ref["coherent"][o]
        c_se = ref["coherent_stderr"][o]
        with np.errstate(divide="ignore", invalid="ignore"):
            r_ref = c_ref[0] / i00
            r_se = c_se[0] / i00
        d = np.abs(np.diagonal(c_ref[0]))
        scored = bool(i00 > 0 and np.max(d) > 0 and c_se[0][np.argmax(d), np.argmax(d)] <= SE_SCORE * np.max(d))
        mi00 = mod["incoherent"][o][0, 0]
        r_mod = mod["coherent"][o][0] / mi00 if mi00 > 0 else np.full((4, 4), np.nan)
        miss = np.abs(r_mod - r_ref)
        if not np.all(np.isfinite(miss)):
            # no paths of this order near backscatter on one side (the model's or the
            # reference's incoherent M00 is 0): nothing to score
            scored = False
            miss = np.nan_to_num(miss, nan=0.0, posinf=0.0)
            r_ref, r_mod, r_se = np.nan_to_num(r_ref), np.nan_to_num(r_mod), np.nan_to_num(r_se)
        k = np.unravel_index(np.argmax(miss - 2 * r_se), miss.shape)
        row: Dict[str, Any] = dict(
            alpha=alpha, theta=theta, material=material, order=oname, scored=scored,
            i00=i00, r_ref=r_ref, r_mod=r_mod, r_se=r_se, worst=k,
            r_verdict=verdict(float(miss[k]), TOL_R, float(r_se[k])) if scored else "–",
            unpaired=None)
        ch = int(np.argmax(np.abs(np.diagonal(r_ref))))
        sign = math.copysign(1.0, r_ref[ch, ch])
        row["channel"] = ch
        for j, (az, _) in enumerate(AZIMUTHS):
            sl = slice(j * nb, (j + 1) * nb)
            w_ref, w_se = half_width(sign * c_ref[sl][:, ch, ch], c_se[sl][:, ch, ch])
            w_mod, _ = half_width(sign * mod["coherent"][o][sl][:, ch, ch])
            rel = abs(w_mod / w_ref - 1) if w_ref > 0 else math.nan
            row[f"w_{az}"] = (w_ref, w_se, w_mod)
            row[f"w_{az}_verdict"] = verdict(rel, TOL_W, w_se / w_ref) if scored else "–"
        rows.append(row)
    return rows


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=Path(__file__).resolve().parents[1], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def diag(m: np.ndarray) -> str:
    return ", ".join(f"{m[i, i]:+.3f}" for i in range(4))


def page(rows: Sequence[Dict[str, Any]], argv: Sequence[str], seconds: float, rays: int) -> str:
    n = {"r": [0, 0], "w": [0, 0]}
    for r in rows:
        if not r["scored"]:
            continue
        n["r"][1] += 1
        n["r"][0] += r["r_verdict"] == "✓"
        for az, _ in AZIMUTHS:
            n["w"][1] += 1
            n["w"][0] += r[f"w_{az}_verdict"] == "✓"
    near = {"r": sum(r["scored"] and r["r_verdict"] == "≈" for r in rows),
            "w": sum(r["scored"] and r[f"w_{az}_verdict"] == "≈" for r in rows for az, _ in AZIMUTHS)}
    out = [
        "# Coherent backscatter: the path banks against the explicit surface",
        "",
        "Generated by `scripts/coherent_backscatter_reference.py` (do not edit by hand). Issue 24, item 3: "
        "the coherent-backscatter enhancement of `orders=\"surface\"` (order 2, and orders 3+) element by "
        "element at exact backscatter, and the half width of its peak in and across the plane of incidence, "
        "against the coherent tally of the explicit microsurface (`pprender.reference.microsurface`, "
        "`src/reference/mod.rs`, \"Coherent backscatter\").",
        "",
        "## What was run",
        "",
        f"- Command: `python {' '.join(shlex.quote(a) for a in argv)}`; {seconds:.0f} s wall "
        f"(reference tallies from the cache where present). pprender {pprender.__version__} from commit "
        f"`{_git('rev-parse', '--short', 'HEAD')}`; {platform.machine()}, {len(__import__('os').sched_getaffinity(0))} CPUs.",
        f"- Reference: Gaussian surfaces ({GRID} x {GRID} cells, correlation length {CORR_LENGTH:g} cells), "
        f"{rays:.3g} rays per cell in 16 batches of fresh surfaces (standard errors from the batches), cone "
        f"{CONE} rad about backscatter, wavelength {WAVELENGTH:g} cell (l / lambda = {CORR_LENGTH / WAVELENGTH:g}), "
        f"bistatic angles 0 to {BETAS[-1]:g} rad in {len(BETAS)} steps, tilted in the plane of incidence "
        "(away from the normal) and across it; the coherent term of each order is `coherent`, its "
        "incoherent counterpart `mueller` of the same cone.",
        "- Model: `Material(\"beckmann\", alpha, eta, orders=\"surface\", wavelength=1e-6, "
        f"correlation_length={CORR_LENGTH:g}e-6)`, default path banks; coherent part = (coherent_backscatter "
        "on) - (off); order 2 from `terms=(\"double\",)`, 3+ from `(\"double\", \"multiple\")` minus order 2 "
        "(its incoherent M00 then includes the small depolarizing remainder past order 8).",
        "- Enhancement R: the coherent Mueller matrix at exact backscatter over the incoherent M00 of the "
        "same order (order 2: 1 in every element where the incoherent normalized element is 1, i.e. R = "
        "M/M00, a 2x enhancement). Target: every element within "
        f"{TOL_R} of the reference's. Half width: of the diagonal element with the largest reference "
        "|R_ii| (ch.; M00 for order 2, often M11 for 3+, whose coherent M00 can be near 0 or negative) "
        "against the bistatic angle, first crossing of half the peak, in the plane of incidence away from "
        f"the normal (in+) and toward it (in-), and across it (out); target within {TOL_W:.0%}.",
        f"- Scored where the reference's peak in that element has a standard error of at most {SE_SCORE:.0%} of "
        "itself (else –). Verdicts: ✓ within the target; ≈ a miss beyond it by at most 2 reference "
        "standard errors; ✗ beyond.",
        "",
        "## Summary",
        "",
        f"- Enhancement (all 16 elements within {TOL_R}): **{n['r'][0]}/{n['r'][1]}** scored (cell, order) "
        f"rows pass, {near['r']} more within 2 se.",
        f"- Half width within {TOL_W:.0%}: **{n['w'][0]}/{n['w'][1]}** pass, {near['w']} more within 2 se.",
        "",
        "## Cells",
        "",
        "R's diagonal (M00, M11, M22, M33), reference ± its largest se / model; the worst element "
        "(largest miss less 2 se); half widths (rad) reference ± se / model.",
        "",
        "| alpha | theta | material | order | I00 (1/sr) | R diag, reference | R diag, model | worst | R | ch. | "
        "hw in+ | | hw in- | | hw out | |",
        "| ---: | ---: | --- | --- | ---: | --- | --- | --- | :-: | :-: | --- | :-: | --- | :-: | --- | :-: |",
    ]
    for r in rows:
        k = r["worst"]
        se = float(np.max(np.diagonal(r["r_se"])))
        if r["i00"] <= 0:
            # no paths of this order near backscatter in the reference
            out.append(f"| {r['alpha']:g} | {r['theta']:g} | {r['material']} | {r['order']} | 0 | "
                       "– | – | – | – | – | – | – | – | – | – | – |")
            continue
        w = []
        for az, _ in AZIMUTHS:
            w_ref, w_se, w_mod = r[f"w_{az}"]
            f = (lambda x: f"{x:.4f}" if math.isfinite(x) else "–")
            ref_s = f"{f(w_ref)}±{f(w_se)}" if math.isfinite(w_ref) else "–"
            w += [f"{ref_s} / {f(w_mod)}", r[f"w_{az}_verdict"]]
        out.append(
            f"| {r['alpha']:g} | {r['theta']:g} | {r['material']} | {r['order']} | {r['i00']:.3g} | "
            f"{diag(r['r_ref'])} ±{se:.3f} | {diag(r['r_mod'])} | M{k[0]}{k[1]} {r['r_ref'][k]:+.3f} / "
            f"{r['r_mod'][k]:+.3f} | {r['r_verdict']} | M{r['channel']}{r['channel']} | " + " | ".join(w) + " |")
    out += [
        "",
        "## Notes",
        "",
        "- The model's R is the interference of the banked paths that leave within 0.1 rad of backscatter "
        "with their reverses, traced facet by facet (`src/brdf/bank/coherent.rs`), over their incoherent "
        "M00; its width is the characteristic function of their 3D separations, with the heights (the "
        "double term of `orders=\"seed\"` takes a Gaussian of the horizontal separation, rms = "
        "`correlation_length`). Both come from the banks' surfaces (seed 1), never the reference's.",
        "- The reference and the model make the same small-angle approximation (J_rev that of exact "
        "backscatter; the bistatic dependence in the phase only). Orders 3+ are few near backscatter "
        "(0.1 rad cone): their rows carry the larger errors on both sides.",
        "- What this page shows beyond the scored rows (measured on this grid, 9.6e7 rays a cell): "
        "orders 3+ of glass get a wider peak from the model at alpha 0.8 (0.0141 against 0.0098 ± 0.0012 "
        "rad at normal incidence; within 6% at alpha 1): `gamma` counts each path once (its intensity with "
        "F = 1, the same for every material), where glass's Fresnel factors weight the paths unevenly. At "
        "50 deg the banks hold few paths of orders 3+ near backscatter: at alpha 0.8 the model's 3+ "
        "coherent term is 0 there (the reference's 3+ is 6% of its order 2 in M00 for the metals), and "
        "its order-2 width toward the normal (in-) comes out wider than the reference's (0.049 against "
        "0.029 ± 0.009 rad for aluminium, unscored). Cells with 0 have no paths of that order near "
        "backscatter in the reference either (alpha 0.5 at 30-50 deg).",
        "- The reference's M11 and M22 of order 2 grow with the bistatic angle on one side of the plane of "
        "incidence at oblique incidence (the odd part of the pair interference, `sin(q . rho)` times the "
        "difference between a path's J and its traced reverse, which is O(cone) for paths leaving off "
        "backscatter): the half widths are taken on the element with the largest enhancement (M00 for "
        "order 2), not on M00 + M11, which that inflated to 0.036-0.043 rad at 30 deg (aluminium, "
        "alpha 0.8). The model keeps the even part only.",
    ]
    return "\n".join(out) + "\n"


def main(argv: Sequence[str]) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    p.add_argument("--alphas", default=",".join(f"{a:g}" for a in ALPHAS))
    p.add_argument("--thetas", default=",".join(f"{t:g}" for t in THETAS))
    p.add_argument("--materials", default=",".join(MATERIALS))
    p.add_argument("--rays", type=float, default=16e6, help="reference rays per cell")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    rows: List[Dict[str, Any]] = []
    for alpha in (float(x) for x in a.alphas.split(",")):
        for theta in (float(x) for x in a.thetas.split(",")):
            for material in a.materials.split(","):
                rows += score_cell(alpha, theta, material, int(a.rays), a.cache)
                print(f"done alpha {alpha:g} theta {theta:g} {material}", file=sys.stderr, flush=True)
    text = page(rows, ["scripts/coherent_backscatter_reference.py", *argv], time.perf_counter() - t0, int(a.rays))
    a.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
