"""The error of interpolating the path banks' tables in alpha (``orders="surface"``,
``src/brdf/orders.rs``: nodes 0.3, 0.4, ..., 1.0; ``OrderTable.mix``: per node, M00 in
``ln(M00 + eps)``, the normalized elements linearly): at the midpoint ``a`` of two nodes, a
bank traced at ``a`` itself against the mix of the two nodes' tables (and, for comparison,
their plain mean), for orders 2 and 3-8, aluminium and glass.

    python scripts/bank_alpha_interpolation.py [MIDPOINTS] [RAYS]
    python scripts/bank_alpha_interpolation.py 0.35,0.55,0.85 4e6

Banks as ``orders="surface"`` traces them (64 surfaces, 256 x 256, correlation length 8,
seed 1; the same seed at every alpha, so the three banks share their random numbers and
the difference is mostly the interpolation's). Directions: backscatter at theta 0 to 80
deg, 30 deg bistatic in the plane (exit 30 deg nearer the normal), and the specular
direction at 20 to 70 deg. Per row: the largest relative M00 difference over the
directions where the midpoint's M00 is at least 1% of its largest, the largest difference
of a normalized element M_ij / M00 there, and, for scale, the largest relative M00
difference between the two nodes themselves.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from pprender import _core

ETAS = (("Al", complex(1.2, 10.4)), ("glass", complex(1.5, 0.0)))
ORDERS = ((2, 2), (3, 8))


def directions() -> tuple[np.ndarray, np.ndarray, list[str]]:
    def d(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
        t, p = np.radians(theta_deg), np.radians(phi_deg)
        return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    wi, wo, names = [], [], []
    for th in range(0, 81, 10):
        wi.append(d(th))
        wo.append(d(th))
        names.append(f"bs {th}")
    for th in range(30, 81, 10):
        wi.append(d(th))
        wo.append(d(th - 30))
        names.append(f"bi30 {th}")
    for th in range(20, 71, 10):
        wi.append(d(th))
        wo.append(d(th, 180.0))
        names.append(f"spec {th}")
    return np.array(wi), np.array(wo), names


def bank(alpha: float, rays: int, seed: int = 1) -> "_core.PathBank":
    return _core.PathBank(alpha, rays, surfaces=64, grid=256, correlation_length=8.0, seed=seed)


def main(argv: list[str]) -> None:
    mids = [float(a) for a in (argv[0] if argv else "0.35,0.55,0.85").split(",")]
    rays = int(float(argv[1])) if len(argv) > 1 else 4_000_000
    wi, wo, names = directions()
    print(f"# alpha interpolation of the banks' tables ({rays:.0e} rays per node)\n")
    print("| midpoint | material | orders | interpolated vs traced: M00, max rel. | linear mix: M00 | "
          "normalized elements, max abs. | where | seed 2 vs seed 1: M00, max rel. | normalized elements | "
          "node vs node: M00, max rel. |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for a in mids:
        t0 = time.perf_counter()
        lo, mid, hi = bank(round(a - 0.05, 10), rays), bank(a, rays), bank(round(a + 0.05, 10), rays)
        other = bank(a, rays, seed=2)
        secs = time.perf_counter() - t0
        for ename, eta in ETAS:
            for orders in ORDERS:
                t_lo, t_mid, t_hi, t_other = (b.table(eta, orders=orders) for b in (lo, mid, hi, other))
                m_lo, m_mid, m_hi, m_other = (t.eval(wi, wo) for t in (t_lo, t_mid, t_hi, t_other))
                interp = t_lo.mix(t_hi, 0.5).eval(wi, wo)
                linear = 0.5 * (m_lo + m_hi)
                m00 = m_mid[:, 0, 0]
                keep = m00 >= 0.01 * m00.max()
                rel = np.abs(interp[:, 0, 0] - m00) / np.where(keep, m00, np.inf)
                k = int(np.argmax(rel))
                rel_linear = np.abs(linear[:, 0, 0] - m00) / np.where(keep, m00, np.inf)
                with np.errstate(divide="ignore", invalid="ignore"):
                    el = np.abs(interp / interp[:, :1, :1] - m_mid / m_mid[:, :1, :1]).max(axis=(1, 2))
                el = np.where(keep, el, 0.0)
                span = np.abs(m_hi[:, 0, 0] - m_lo[:, 0, 0]) / np.where(keep, m00, np.inf)
                noise = np.abs(m_other[:, 0, 0] - m00) / np.where(keep, m00, np.inf)
                with np.errstate(divide="ignore", invalid="ignore"):
                    el_noise = np.abs(m_other / m_other[:, :1, :1] - m_mid / m_mid[:, :1, :1]).max(axis=(1, 2))
                el_noise = np.where(keep, el_noise, 0.0)
                print(f"| {a:g} | {ename} | {orders[0]}-{orders[1]} | {rel.max():.3f} | {rel_linear.max():.3f} | "
                      f"{el.max():.3f} | "
                      f"{names[k]} | {noise.max():.3f} | {el_noise.max():.3f} | {span.max():.3f} |", flush=True)
        print(f"\n(banks at {a - 0.05:g}, {a:g}, {a + 0.05:g}: {secs:.0f} s)\n", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
