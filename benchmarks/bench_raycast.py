"""Ray-casting benchmark: closest hits per second of the renderer's tree, walked in f64 on
the CPU and in the WGSL kernel on an adapter, with Embree (through trimesh) beside them.

``python benchmarks/bench_raycast.py [--write [PATH]] [--device auto|cpu|gpu ...] [--rays N]``
prints a markdown report (``--write``: also to ``docs/raycast-benchmark.md``).

Why: inter-reflections (``bounces`` 2 and 3) trace their paths in f64 on the CPU, and the
tree walk is about 30% of their time (issue 23's profile). Whether paths traced in a kernel
would pay, on lavapipe's vectorized CPU or on a GPU, starts with how fast the same tree is
walked there. This measures that one step, on the same rays, in one run.

Meshes: the default 3U CubeSat of :func:`pprender.models.cubesat` (bus, deployed wings,
whip antenna, 11,840 triangles) and the same wrapped in MLI at ``detail=7`` (1,314,880
triangles). Rays, ``--rays`` of each kind, from a fixed seed:

- *primary*: parallel rays along a random direction, their origins uniform over the disk of
  the mesh's bounding sphere, outside it (the receiver's view: about half hit);
- *secondary*: from points uniform over the mesh's area (``trimesh.sample``), leaving on the
  face normal's side in cosine-weighted directions, the origin 1e-6 of the mesh's size off
  the surface (the paths' bounce rays: most escape, some meet another part).

Casters (each finds the closest hit, ``t > 0``):

- ``f64``: :func:`pprender._core.ray_cast_timed` with ``device="f64"``, the tree the
  paths use (``render::bvh::Bvh``), rays shared among rayon's threads;
- ``kernel (<adapter>)``: the same call with ``device=`` an adapter: the same tree in f32
  (``shaders/raycast.wgsl``, one invocation per ray), rays uploaded and hits read back in
  chunks of 2^20, the pipeline built once a call;
- ``Embree (1 thread)``: embreex's ``EmbreeScene.run`` (Embree's ``rtcIntersect1`` per
  ray, f32, its SIMD within a ray, one thread), through trimesh's wrapper
  (``trimesh.ray.ray_pyembree``), its scene built before the timing: the field's CPU ray
  caster, as a yardstick.

The rates are ``--rays`` over the walk's seconds, best of ``--repeats`` calls: for the tree
those the call reports apart from its build; for the kernel they include building its
pipeline, uploading the tree and the rays and reading the hits back. Agreement against
``f64``: rays where one caster hits and the other misses, and the largest ``|t - t_f64|``
(relative to the mesh's size) where both hit.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np
import trimesh

import pprender
from pprender import _core, models
from bench import cpu_model, emit_report, load_average, threads_available
from bench_render import best_time

MESHES = (("CubeSat 3U", {}), ("CubeSat 3U, MLI detail 7", {"wrap": True, "detail": 7}))


def rays(mesh: trimesh.Trimesh, kind: str, n: int, seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    center = mesh.bounding_sphere.primitive.center
    radius = float(mesh.bounding_sphere.primitive.radius)
    if kind == "primary":
        view = rng.normal(size=3)
        view /= np.linalg.norm(view)
        a = np.cross(view, [1.0, 0.0, 0.0] if abs(view[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(view, a)
        r = radius * np.sqrt(rng.random(n))
        phi = 2 * np.pi * rng.random(n)
        o = center + 1.5 * radius * view + (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b
        d = np.tile(-view, (n, 1))
        return o, d
    pts, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    nrm = mesh.face_normals[face]
    # cosine-weighted about the normal (Malley): a uniform point of the disk lifted up
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    t1 = np.cross(nrm, np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    d = (r * np.cos(phi))[:, None] * t1 + (r * np.sin(phi))[:, None] * t2 + np.sqrt(1 - u1)[:, None] * nrm
    o = pts + 1e-6 * 2 * radius * nrm
    return o, d


def agreement(t: np.ndarray, ref: np.ndarray, size: float) -> tuple[int, int, float]:
    """Rays one hits and the other misses; rays both hit with ``|t - t_ref|`` over 1e-5 of
    ``size``; the largest ``|t - t_ref|`` over ``size`` where both hit."""
    hit, ref_hit = np.isfinite(t), np.isfinite(ref)
    both = hit & ref_hit
    dt = np.abs(t[both] - ref[both]) / size
    return int(np.sum(hit != ref_hit)), int(np.sum(dt > 1e-5)), float(dt.max()) if both.any() else 0.0


def _embree(mesh: trimesh.Trimesh) -> Any:
    """trimesh's wrapper of an Embree scene of ``mesh``, or None without embreex (the GPU
    machine's bundle has none)."""
    try:
        from trimesh.ray import ray_pyembree
        return ray_pyembree.RayMeshIntersector(mesh)._scene
    except (ImportError, AttributeError):
        return None


def measure(devices: list[str], n: int, repeats: int,
            meshes: tuple[tuple[str, dict[str, Any]], ...] = MESHES) -> list[dict[str, Any]]:
    """The table's rows: per mesh and kind of rays, ``f64``, then each of ``devices``'
    kernels, then Embree where it is installed."""
    rows = []
    for name, kw in meshes:
        mesh = models.cubesat("3U", **kw)
        v = np.asarray(mesh.vertices, float)
        f = np.asarray(mesh.faces, np.int64)
        size = 2 * float(mesh.bounding_sphere.primitive.radius)
        embree = _embree(mesh)  # its scene built here, before any timing
        for kind in ("primary", "secondary"):
            o, d = rays(mesh, kind, n)
            ref_t = None
            for caster in ["f64", *devices]:
                _core.ray_cast(v, f, o[:64], d[:64], device=caster)  # warm-up: device, shaders
                runs = [_core.ray_cast_timed(v, f, o, d, device=caster) for _ in range(repeats)]
                t_hits = runs[0][0]
                if ref_t is None:
                    ref_t = t_hits
                walk = min(r[2]["walk"] for r in runs)
                build = min(r[2]["build"] for r in runs)
                label = "f64" if caster == "f64" else f"kernel ({_core.device_info(caster)['name']})"
                differ, off, dt = agreement(t_hits, ref_t, size)
                rows.append(dict(mesh=name, tris=len(f), rays=kind, caster=label, rate=n / walk,
                                 build=build, hit=float(np.mean(np.isfinite(t_hits))),
                                 differ=differ, off=off, dt=dt))

            if embree is None:
                continue

            def embree_t() -> np.ndarray:
                out = embree.run(o, d, output=1)
                return np.where(out["primID"] >= 0, out["tfar"] / embree.scale, np.inf)

            embree_t()  # warm-up
            t_e = best_time(embree_t, repeats)[0]
            t_hits = embree_t()
            differ, off, dt = agreement(t_hits, ref_t, size)
            rows.append(dict(mesh=name, tris=len(f), rays=kind, caster="Embree (1 thread)",
                             rate=n / t_e, build=float("nan"), hit=float(np.mean(np.isfinite(t_hits))),
                             differ=differ, off=off, dt=dt))
    return rows


def table(rows: list[dict[str, Any]]) -> list[str]:
    """The markdown table of :func:`measure`'s rows."""
    lines = [
        "| mesh | triangles | rays | hit | caster | Mrays/s | ratio | tree build (s) | differ | t off | max dt |",
        "| --- | ---: | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    ref = {(r["mesh"], r["rays"]): r["rate"] for r in rows if r["caster"] == "f64"}
    for r in rows:
        build = "" if not np.isfinite(r["build"]) else f"{r['build']:.3f}"
        lines.append(
            f"| {r['mesh']} | {r['tris']:,} | {r['rays']} | {100 * r['hit']:.0f}% | {r['caster']} "
            f"| {r['rate'] / 1e6:.2f} | {r['rate'] / ref[(r['mesh'], r['rays'])]:.2f}x | {build} "
            f"| {r['differ']} | {r['off']} | {r['dt']:.1e} |")
    return lines


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Each caster's rate against the f64 tree's, the range over the table's rows."""
    ref = {(r["mesh"], r["rays"]): r["rate"] for r in rows if r["caster"] == "f64"}
    out = []
    for caster in dict.fromkeys(r["caster"] for r in rows if r["caster"] != "f64"):
        ratios = [r["rate"] / ref[(r["mesh"], r["rays"])] for r in rows if r["caster"] == caster]
        out.append(f"- {caster}: {min(ratios):.2f}x to {max(ratios):.2f}x the f64 tree's rate "
                   f"over the {len(ratios)} rows.")
    return out


def report(rows: list[dict[str, Any]], n: int, repeats: int, devices: list[str]) -> str:
    cmd = "python benchmarks/bench_raycast.py --write" + "".join(f" --device {d}" for d in devices)
    lines = [
        "# Ray-casting benchmark",
        "",
        f"Generated by `{cmd}` (`--rays {n}`, best of {repeats}); the set-up is in the "
        "script's docstring. CPU: " + cpu_model() + f", {threads_available()} threads, "
        f"load average {load_average()}; pprender {pprender.__version__}, trimesh "
        f"{trimesh.__version__}.",
        "",
        "Rate: closest hits per second of the walk, best of the calls (for the kernel: "
        "the pipeline's compilation, the uploads, the dispatches and the read-back; the "
        "tree's build apart, in its own column). Ratio: the rate over the f64 tree's on the "
        "same rays, in this run. Differ: rays one caster hits and `f64` misses or the "
        "reverse; t off: rays both hit, `|t - t_f64|` over 1e-5 of the mesh's size (a ray "
        "through a crack between triangles in f32 meets a farther one); max dt: the "
        "largest `|t - t_f64|` where both hit, over the mesh's size.",
        "",
        *table(rows),
        "",
        *summary(rows),
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/bench_raycast.py", description=__doc__.splitlines()[0])
    p.add_argument("--device", action="append", default=None,
                   help="an adapter for the kernel (auto, cpu, gpu); repeat for several (default: cpu)")
    p.add_argument("--rays", type=int, default=1_000_000)
    p.add_argument("-r", "--repeats", type=int, default=3)
    p.add_argument("--write", nargs="?", const=True, default=False, metavar="PATH")
    a = p.parse_args(argv)
    devices = a.device or ["cpu"]
    rows = measure(devices, a.rays, a.repeats)
    emit_report(report(rows, a.rays, a.repeats, devices), a.write, "raycast-benchmark.md", quiet=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
