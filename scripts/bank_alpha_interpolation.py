"""The error of interpolating the path banks' tables in alpha (``orders="surface"``,
``src/brdf/orders.rs``, ``src/brdf/orders/similar.rs``): at the geometric midpoint ``a`` of
two neighbouring roughness nodes, a bank traced at ``a`` itself against the interpolation
of the two nodes' tables, for orders 2 and 3-8, aluminium and glass.

    python scripts/bank_alpha_interpolation.py [--intervals 0.05:0.075,...] [--rays 4e6]
                                               [--write docs/bank-alpha-interpolation.md]

Compared, per interval:
- ``similar``: what ``orders="surface"`` does (``OrderTable.mix_alpha``): M00 read at the
  similar angles (``cot theta`` scaled by ``a_node / alpha``) and mixed in ``ln M00``, the
  normalized elements mixed at the actual angles;
- ``fixed``: the nodes' tables mixed at the same ``(theta_i, theta_o, phi)``
  (``OrderTable.mix``, what the banks did before alpha 0.05-0.3 had nodes);
- ``noise``: a second bank at ``a`` with another seed against the first (the banks' own
  Monte Carlo error, which bounds what the comparison can resolve).

Banks as ``orders="surface"`` traces them (64 surfaces, 256 x 256, correlation length 8,
seed 1, so the banks share their random numbers; the noise bank seed 2), unthinned.
Per incidence node ``theta_i`` the error is the L1 distance of M00 over the exit hemisphere
(nodes weighted by ``cos(theta_o)`` solid angle) relative to the midpoint bank's albedo;
the table reports its largest value over the incidence nodes where the midpoint's albedo
of those orders is at least 1e-3 ("strong") and over those where it is 1e-4 to 1e-3
("onset"), and the largest error of a normalized element M_ij / M00 over the exit nodes
with M00 at least 10% of that incidence node's largest.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import pprender
from pprender import _core

ETAS = (("aluminium", complex(1.3763, 10.2449)), ("glass", complex(1.5, 0.0)))
ORDERS = ((2, 2), (3, 8))
DEFAULT_INTERVALS = "0.05:0.075,0.075:0.1,0.1:0.15,0.15:0.2,0.2:0.25,0.25:0.3,0.5:0.6,0.8:0.9"
STEP = math.pi / 72
THETA = np.arange(36) * STEP
# cos(theta_o) solid-angle weight of each exit node (phi over [0, pi], trapezoid ends)
WEIGHT = (np.cos(THETA) * np.sin(THETA))[:, None] * np.ones(25)[None, :]
WEIGHT[:, [0, -1]] *= 0.5
ALBEDO_SCALE = 2.0 * STEP * math.pi / 24  # node sum -> albedo (both halves of phi)


def bank(alpha: float, rays: int, seed: int) -> "_core.PathBank":
    return _core.PathBank(alpha, rays, surfaces=64, grid=256, correlation_length=8.0, seed=seed)


def errors(test: np.ndarray, ref: np.ndarray) -> dict:
    """Per incidence node: albedo of ``ref``, relative L1 of M00, max normalized-element error."""
    m, x = ref[..., 0, 0], test[..., 0, 0]
    out = []
    for i in range(36):
        albedo = float((m[i] * WEIGHT).sum() * ALBEDO_SCALE)
        if albedo <= 0.0:
            continue
        l1 = float((np.abs(x[i] - m[i]) * WEIGHT).sum() / (m[i] * WEIGHT).sum())
        keep = m[i] >= 0.1 * m[i].max()
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.abs(test[i] / test[i][..., :1, :1] - ref[i] / ref[i][..., :1, :1]).max(axis=(-1, -2))
        el = float(np.nanmax(np.where(keep, d, 0.0)))
        out.append((i * 2.5, albedo, l1, el))
    return out


def summarize(rows: list) -> tuple:
    strong = [r for r in rows if r[1] >= 1e-3]
    onset = [r for r in rows if 1e-4 <= r[1] < 1e-3]
    f = lambda rs, k: max((r[k] for r in rs), default=float("nan"))  # noqa: E731
    worst = max(strong, key=lambda r: r[2], default=None)
    return f(strong, 2), (worst[0] if worst else float("nan")), f(onset, 2), f(strong, 3), len(strong)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--intervals", default=DEFAULT_INTERVALS, help="lo:hi pairs of roughness nodes")
    p.add_argument("--rays", type=float, default=4e6, help="primary rays per incidence node of each bank")
    p.add_argument("--write", type=Path, default=None, help="write the markdown page here")
    args = p.parse_args()
    rays = int(args.rays)
    intervals = [tuple(float(v) for v in s.split(":")) for s in args.intervals.split(",")]
    t_start = time.perf_counter()
    lines = []
    a = lines.append
    a("| interval | midpoint | material | orders | strong: similar | fixed | noise | at theta_i | "
      "onset: similar | fixed | noise | normalized: similar | noise |")
    a("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(lines), flush=True)
    cache: dict = {}
    for lo, hi in intervals:
        mid = round(math.sqrt(lo * hi), 4)
        t0 = time.perf_counter()
        for k in list(cache):
            if k not in ((lo, 1), (hi, 1)):
                del cache[k]
        for key in ((lo, 1), (hi, 1), (mid, 1), (mid, 2)):
            if key not in cache:
                cache[key] = bank(key[0], rays, key[1])
        b_lo, b_hi, b_mid, b_noise = cache[(lo, 1)], cache[(hi, 1)], cache[(mid, 1)], cache[(mid, 2)]
        for name, eta in ETAS:
            for orders in ORDERS:
                t_lo, t_hi, t_mid, t_noise = (b.table(eta, orders=orders) for b in (b_lo, b_hi, b_mid, b_noise))
                ref = t_mid.data
                w = math.log(mid / lo) / math.log(hi / lo)
                sim = summarize(errors(t_lo.mix_alpha(t_hi, lo, hi, mid).data, ref))
                fix = summarize(errors(t_lo.mix(t_hi, w).data, ref))
                noise = summarize(errors(t_noise.data, ref))
                if sim[4] == 0:
                    continue
                row = (f"| {lo:g}-{hi:g} | {mid:g} | {name} | {orders[0]}-{orders[1]} | {sim[0]:.3f} | {fix[0]:.3f} | "
                       f"{noise[0]:.3f} | {sim[1]:g} | {sim[2]:.3f} | {fix[2]:.3f} | {noise[2]:.3f} | "
                       f"{sim[3]:.3f} | {noise[3]:.3f} |")
                lines.append(row)
                print(row, flush=True)
        del cache[(mid, 1)], cache[(mid, 2)]
        print(f"# {lo:g}-{hi:g}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    wall = time.perf_counter() - t_start
    if args.write is None:
        return
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    page = [
        "# The path banks' tables between roughness nodes (issue 24)",
        "",
        "Generated by `scripts/bank_alpha_interpolation.py` (do not edit by hand). `orders=\"surface\"` "
        "traces path banks at roughness nodes (`ALPHA_NODES` in `src/brdf/orders.rs`: 0.05, 0.075, 0.1, 0.15, "
        "0.2, 0.25, 0.3, 0.4, ..., 1.0) and interpolates their tables in between; this page measures that "
        "interpolation against banks traced at the midpoints of the intervals "
        f"{', '.join(f'{lo:g}-{hi:g}' for lo, hi in intervals)}.",
        "",
        "## What was run",
        "",
        f"- Command: `python scripts/bank_alpha_interpolation.py --intervals {args.intervals} --rays {args.rays:g} "
        f"--write {args.write}`; {wall:.0f} s wall.",
        f"- pprender {pprender.__version__} from a checkout at commit `{commit}`; {platform.machine()}, "
        f"{os.cpu_count()} CPUs.",
        f"- Banks: {rays:.0e} primary rays per incidence node, 64 surfaces of 256 x 256 cells, correlation "
        "length 8 cells, unthinned; the nodes and the midpoint with seed 1 (shared random numbers), the noise "
        "bank at the midpoint with seed 2.",
        "- Materials: aluminium eta = 1.3763+10.2449i, glass eta = 1.5.",
        "",
        "## Method",
        "",
        "- `similar` is what `orders=\"surface\"` does (`src/brdf/orders/similar.rs`): with small slopes and "
        "grazing directions the paths' geometry is unchanged when the heights and the directions' vertical "
        "components scale together, so node `a`'s M00 is read at `cot theta' = (a / alpha) cot theta` (both "
        "polar angles) and the two nodes' values are mixed in `ln M00` with the weight "
        "`ln(alpha / a_lo) / ln(a_hi / a_lo)`; the normalized elements M / M00 are mixed at the actual angles "
        "(the facets' local incidence is close to the macroscopic one, so their Fresnel is).",
        "- `fixed` mixes the two nodes' tables at the same angles with the same weight (`OrderTable.mix`).",
        "- `noise` is a second bank at the midpoint with another seed, against the first: what the "
        "comparison cannot resolve.",
        "- Per incidence node: L1 distance of M00 over the exit nodes (weighted by cos(theta_o) solid angle), "
        "relative to the midpoint bank's; the largest over the incidence nodes where the midpoint's albedo "
        "of those orders is at least 1e-3 (strong, with the node where the similar mix is worst) or 1e-4 to "
        "1e-3 (onset); and the largest error of a normalized element M_ij / M00 over exit nodes with M00 at "
        "least 10% of that incidence node's largest (strong incidence nodes). Rows without a strong "
        "incidence node are left out.",
        "",
        "## Results",
        "",
        *lines,
        "",
    ]
    args.write.write_text("\n".join(page))
    print(f"wrote {args.write}", file=sys.stderr)


if __name__ == "__main__":
    main()
