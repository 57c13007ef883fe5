"""Cost of ``Material(orders="surface")`` (issue 24): the cold build of a roughness node's
path bank, a material at any alpha once its two nodes are cached, and evaluations per
second against the seed's double term, in one process.

Run ``python benchmarks/bench_surface_orders.py [--rays N]``; prints a table.

* **Cold node**: the first material at alpha 0.8 (a node) traces the node's bank
  (``bank_rays`` primary rays at each of 36 incidence nodes on 64 surfaces) and builds
  its tables (order 2 and orders 3+, with the material's Fresnel and with F = 1). The
  banks go to a fresh temporary disk cache (``pprender.set_cache_dir``), so that a warm
  cache on the machine never hides the cold cost.
* **Cold node, new process**: the same material in a new process, its bank read from
  that disk cache (the read and the tables; includes the interpreter's start).
* **New index at a cached node**: another eta at alpha 0.8 (tables only).
* **Between nodes, cold**: alpha 0.75 needs node 0.7 (traced) and 0.8 (cached).
* **Any alpha, nodes cached**: alpha 0.72, 0.74, 0.76, 0.78 with the same eta (the
  tables interpolated in alpha, the albedo tables): the mean over the four.
* **Evaluations**: ``pprender.brdf`` of the full material (single + double + multiple) on
  20,000 random direction pairs, surface orders against the seed's double term (order
  160), best of 3.
"""

import argparse
import subprocess
import sys
import tempfile
import time

import numpy as np

import pprender


def _timed(f):
    t = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t


def main(rays: int = 4_000_000) -> str:
    terms = ("single", "double", "multiple")

    def mat(alpha: float, eta: complex, orders: str = "surface") -> pprender.Material:
        return pprender.Material("beckmann", alpha=alpha, eta=eta, terms=terms, orders=orders, bank_rays=rays)

    rows = []
    cache = tempfile.TemporaryDirectory(prefix="pprender-bench-cache-")
    pprender.set_cache_dir(cache.name)
    _, t = _timed(lambda: mat(0.8, 0.2 + 3.4j))
    rows.append(("cold node (alpha 0.8): bank + tables", t))
    code = (
        "import pprender; pprender.set_cache_dir(%r); pprender.Material('beckmann', alpha=0.8, eta=0.2+3.4j, "
        "terms=%r, orders='surface', bank_rays=%d)" % (cache.name, terms, rays)
    )
    _, t = _timed(lambda: subprocess.run([sys.executable, "-c", code], check=True))
    rows.append(("cold node, new process: bank read from the disk cache + tables", t))
    _, t = _timed(lambda: mat(0.8, 1.5 + 0j))
    rows.append(("new eta at a cached node (alpha 0.8, glass)", t))
    _, t = _timed(lambda: mat(0.75, 0.2 + 3.4j))
    rows.append(("between nodes, one cold (alpha 0.75: node 0.7 traced)", t))
    ts = [_timed(lambda a=a: mat(a, 0.2 + 3.4j))[1] for a in (0.72, 0.74, 0.76, 0.78)]
    rows.append(("any alpha, nodes cached (0.72-0.78, mean of 4)", float(np.mean(ts))))
    rng = np.random.default_rng(7)
    v = rng.normal(size=(2, 20_000, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = v[0], v[1]
    evals = {}
    for orders in ("surface", "seed"):
        m = mat(0.75, 0.2 + 3.4j, orders)
        pprender.brdf(m, wi[:10], wo[:10])
        best = min(_timed(lambda: pprender.brdf(m, wi, wo))[1] for _ in range(3))
        evals[orders] = len(wi) / best
    lines = [
        f"Material(orders=\"surface\"), bank_rays={rays:,}, pprender {pprender.__version__}",
        "",
        "| step | seconds |",
        "| --- | ---: |",
    ]
    lines += [f"| {name} | {t:.3f} |" for name, t in rows]
    lines += [
        "",
        "| full material (single + double + multiple), alpha 0.75 | evaluations/s |",
        "| --- | ---: |",
        f"| orders=\"surface\" | {evals['surface']:,.0f} |",
        f"| orders=\"seed\" (double term by quadrature, order 160) | {evals['seed']:,.0f} |",
        f"| ratio | {evals['surface'] / evals['seed']:.0f}x |",
    ]
    text = "\n".join(lines)
    print(text)
    cache.cleanup()
    return text


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=int, default=4_000_000, help="bank_rays (primary rays per incidence node)")
    a = ap.parse_args()
    main(a.rays)
