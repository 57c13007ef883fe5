"""Multiview against one raster pass per layer, in one run: realizations per second of the
render benchmark's CubeSat (128x128, one visibility sample) with ``PPRENDER_RASTER_VIEWS=1``
and with the device's own view count, alternating fresh processes (the setting is read
when a process opens the device), and a fingerprint of the outputs of each, which must be
equal (multiview draws every layer with the same arithmetic).

``python benchmarks/bench_raster_views.py [--device gpu|cpu|auto] [--rounds 2] [--batches 64 256 2048]
[--resolution 128] [--terms single double multiple]`` (the fingerprint renders use half the
resolution; ``--terms`` are the aluminium parts' BRDF terms, ``single`` for a quick test that
it runs).

On lavapipe (6 views) the passes are cheap and the rates close; on an NVIDIA H200 (31
views, 2026-11-26) the profile-only rates went from 13,200-14,800 to 20,900-22,200/s at
batch 256 (docs/rendering.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def child(device: str, batches: list[int], resolution: int, terms: tuple[str, ...]) -> dict:
    """In a fresh process: the view count, the outputs' fingerprint and the rates."""
    import numpy as np

    import pprender
    from bench_render import best_time, cubesat_scene, random_quaternions

    scene = cubesat_scene(terms)
    h = hashlib.sha256()
    q = random_quaternions(37, seed=9)
    small = max(8, resolution // 2)
    for kw in (dict(resolution=small), dict(resolution=small, pixel_samples=2),
               dict(resolution=small, bistatic_angle=0.2)):
        r = pprender.render(scene, pprender.Lidar(**kw), q, outputs=("profile", "mueller", "range"), device=device)
        for a in (r.profile, r.mueller, r.range, r.coverage):
            h.update(np.ascontiguousarray(a).tobytes())
    rows = []
    for label, sensor, outputs in [
        ("profile only (Stokes, H)", pprender.Lidar(resolution=resolution, pixel_samples=1,
                                                    polarization=[1, 1, 0, 0]), ("profile",)),
        ("full model", pprender.Lidar(resolution=resolution, pixel_samples=1), ("profile", "mueller", "range")),
    ]:
        for n in batches:
            qn = random_quaternions(n, seed=n)

            def once() -> None:
                pprender.render(scene, sensor, qn, outputs=outputs, device=device)

            once()
            once()
            best, median = best_time(once, 5)
            rows.append({"request": label, "batch": n, "best": n / best, "median": n / median})
    return {"views": pprender.device_info(device)["raster_views"], "hash": h.hexdigest()[:16], "rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="auto", choices=("gpu", "cpu", "auto"))
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--batches", type=int, nargs="+", default=[64, 256, 2048])
    ap.add_argument("--resolution", type=int, default=128, help="pixels a side of the timed renders")
    ap.add_argument("--terms", nargs="+", default=["single", "double", "multiple"],
                    help="BRDF terms of the aluminium bus and antenna")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        sys.path.insert(0, HERE)
        print(json.dumps(child(a.device, a.batches, a.resolution, tuple(a.terms))))
        return 0
    runs = []
    for _ in range(a.rounds):
        for views in ("1", None):
            env = {k: v for k, v in os.environ.items() if k != "PPRENDER_RASTER_VIEWS"}
            if views is not None:
                env["PPRENDER_RASTER_VIEWS"] = views
            cmd = [sys.executable, os.path.abspath(__file__), "--child", "--device", a.device,
                   "--resolution", str(a.resolution), "--batches", *map(str, a.batches), "--terms", *a.terms]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
    hashes = {r["hash"] for r in runs}
    print("| raster views | request | batch | realizations/s, best | median |")
    print("|---:|---|---:|---:|---:|")
    for r in runs:
        for row in r["rows"]:
            print(f"| {r['views']} | {row['request']} | {row['batch']} | {row['best']:.1f} | {row['median']:.1f} |")
    print()
    print(f"outputs identical across view counts: {'yes' if len(hashes) == 1 else 'NO'} ({', '.join(sorted(hashes))})")
    return 0 if len(hashes) == 1 else 1


if __name__ == "__main__":
    sys.exit(main())
