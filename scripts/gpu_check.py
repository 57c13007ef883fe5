"""The one-call GPU check: which adapter renders, does its f32 kernel agree with the f64
CPU twin, and how fast is it, written to ``docs/gpu-benchmark.md``.

Run through ``scripts/gpu_check.sh`` on a machine with only Python, NumPy and the wheels
of ``scripts/gpu_bundle.sh`` (no Rust, no Mitsuba, no registry), or directly::

    python scripts/gpu_check.py [--device gpu|cpu|auto] [--write PATH] [--budget SECONDS]

1. ``pprender.device_info(device)``: the adapter, backend, driver and limits.
2. Agreement: standard scenes (the 3U CubeSat with body panels at analytic coverage, a
   smooth rough-aluminium sphere, the default 3U CubeSat with
   single + double + multiple scattering, a bistatic tilted plate) rendered by the device
   kernel (``arithmetic="f32"``) and by its f64 CPU twin (``arithmetic="f64"``: the same
   tables, visibility samples and pulse integration in double precision). What differs
   is f32 arithmetic, rasterizer ties (a sample exactly on an edge between two surfaces
   can land on either: one pixel of a few thousand then sees another surface, and a
   total or profile can move by ~2e-3) and, bistatic, the cast-shadow test (a shadow map
   on the device, exact rays in the twin). Graded per pixel, on pixels above 1% of the
   brightest: the 99th percentile of the largest Mueller/Stokes-element error relative
   to the pixel's intensity, and the fraction of outlier pixels (error above 1e-2: ties,
   or a broken kernel when there are many). The totals' and profiles' relative errors
   are graded loosely (ties). Limits are well above what lavapipe measures here
   (docs/gpu-benchmark.md lists both), loose enough for another device's f32
   transcendental functions, tight enough to catch a wrong kernel.
   Then roll invariance: monostatic single bounce, the body-panel CubeSat's cross-section
   must not change as it rolls about the line of sight (16 rolls, 48 px, analytic
   coverage; the device twin of ``test_analytic_coverage_total_is_invariant_under_roll``).
3. Illuminated area: the ``"illuminated_area"`` output (per range bin, the effective
   projected area of the lit surface, accumulated beside the profile) of the 3U CubeSat,
   four attitudes at 96x96, device kernel against the f64 twin, on the bins above 1% of
   each attitude's peak S0. Graded: the median relative error, and every bin's error
   against what rasterizer ties explain: a tie moves a bin's S0 profile and its area
   together (up to tens of percent in a faint bin), so a bin may differ by
   ``area_bin + area_tie`` x its own S0 profile difference; the profile's relative L1
   error as in 2 (a broken profile must not excuse the area).
4. Surface orders: a sphere of a ``Material(..., orders="surface")`` (Beckmann alpha 0.6,
   aluminium, single + double + multiple from a 20,000-ray path bank: the single term's
   masking calibrated to the traced surface, a table the kernel reads), with
   ``brdf="shader"`` and ``brdf="table"``, one attitude at 96x96, device against twin,
   graded per pixel as in 2 (99th percentile) and on the total. The path bank is traced
   in memory (the disk cache is off during the check): a few seconds, in the one-off costs.
5. Throughput: realizations (attitudes) per second of the CubeSat at 128x128, for a
   profile-only Stokes request and for the full model (Mueller profile + image + range),
   batch sizes doubling from 1 until two doublings in a row each add less than 10% (the
   plateau) or the time budget runs out. Rates are batch / best and batch / median of 7
   calls after 2 warm-up calls, timed after 2 s of rendering to bring the clocks up
   (device creation, shader compilation and BRDF tables excluded and listed separately).
6. Where the time goes: each output alone and all together at one batch size, with the
   stages of the best call (``RenderResult.stage_seconds``: encoding, waiting for the
   device, reading back and decoding, conversion to NumPy).
7. Inter-reflections (skipped with ``--quick``): the render benchmark's table
   (``benchmarks/bench_render.py``, ``interreflection_rows``) on this machine: bounces 1 to 3
   at 4 and 16 paths per pixel, the first hits on the device and the paths on the CPU's
   threads (no GPU kernel traces paths yet), beside the f64 CPU twin, with the profile noise
   against a 1024-path reference.
8. What the device time scales with: profile-only renders of SCALING_BATCH attitudes at
   several resolutions and triangle counts, the device's time per attitude from the
   stages. Time that stays put as pixels and triangles grow is per-attitude overhead
   (render passes, dispatches), not shading or rasterization.
9. Ray casting (``benchmarks/bench_raycast.py``): closest hits per second of the
   renderer's tree walked in f32 by ``shaders/raycast.wgsl`` on the device, against the
   same tree walked in f64 on the CPU's threads, on the 3U CubeSat (and, without
   ``--quick``, the same wrapped in MLI, 1.3 million triangles): the first step of paths
   traced in a kernel (issue 23), measured. With ``--quick``: 2,000 rays, the small mesh.

Exit status 1 if any graded check (2, 3, 4) fails, 2 if the requested device is missing.
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import sys
import time
from typing import Any

import numpy as np

import pprender
from pprender import materials, models

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "benchmarks"))
import bench_raycast  # noqa: E402  (the ray-casting benchmark's)
from bench_render import best_time, cubesat_scene, interreflection_rows, random_quaternions  # noqa: E402  (the render benchmark's)

#: Largest allowed errors of the f32 kernel against the f64 twin (module docstring).
LIMITS = {
    # 2, agreement (AGREEMENT: the keys graded there)
    "total": 1e-2, "profile": 1e-2, "image_p99": 1e-3, "outliers": 2e-3,
    # 3, illuminated area: lavapipe and an H200 measure a median of 2e-6 (limit 50x
    # above; an area more than 1e-4 off everywhere fails). A bin may differ by area_bin +
    # area_tie x its own S0 profile difference: where the profile agrees to 1e-5, the
    # area does to <= 2.7e-4 on lavapipe (16 attitudes at 64, 96 and 128 px); where a
    # rasterizer tie moves the profile (up to 57% in a faint bin), the area moved by at
    # most 3.8x what the profile did beyond 1e-3 (at 96 px: 0.42 where the profile moved
    # 0.57). A bin's area more than 0.11% off where the profile agrees to 1e-5 fails.
    "area_median": 1e-4, "area_bin": 1e-3, "area_tie": 10.0,
    # 4, surface orders: lavapipe measures p99 4.5e-5 and total 8.6e-5, an H200 3.6e-5
    # and 2.6e-5 (50k-ray bank; limits 10-20x above). A kernel that skipped the
    # calibration table (the twin's render with the uncalibrated single term in place of
    # the calibrated one) measures p99 1.3e-2 and total 5.7e-3: 13x and 6x over.
    "surface_p99": 1e-3, "surface_total": 1e-3,
}
#: The keys of LIMITS that ``agreement`` grades.
AGREEMENT = ("total", "profile", "image_p99", "outliers")
#: A pixel whose error exceeds this (relative to its intensity) is an outlier.
OUTLIER = 1e-2
RES = 128


@functools.cache
def cubesat() -> pprender.Scene:
    """The render benchmark's 3U CubeSat (``benchmarks/bench_render.py``): aluminium bus and
    antenna with single + double + multiple scattering, glass-covered cells, white paint.
    One scene for the whole check: its materials take seconds to build on 2 cores."""
    return cubesat_scene()


#: Sensor settings of the analytic-coverage rows: exact pixel areas of each visible part
#: (with the outline lists of src/render/thin.rs), 2x2 sub-pixels.
ANALYTIC: dict[str, Any] = {"coverage": "analytic", "supersampling": 2, "polarization": [1.0, 1.0, 0.0, 0.0]}


def body_panels() -> pprender.Scene:
    """The 3U CubeSat with body-mounted panels of ``tests/test_render.py``'s roll test:
    single-bounce aluminium bus, glass cells, Lambertian backs."""
    mesh = models.cubesat("3U", panels="body", antenna=False, detail=1)
    return pprender.Scene(mesh, {
        "bus": pprender.Material("beckmann", alpha=0.2, eta=1.38 + 10.2j, terms=["single"]),
        "solar_cells": pprender.Material("beckmann", alpha=0.05, eta=1.5 + 0j, terms=["single"]),
        "panel_back": pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.8),
    })


#: Largest change of the cross-section (any Stokes component, relative to S0) over the
#: rolls of ``roll_invariance`` (tests/test_render.py's limit; lavapipe measures <= 5e-5).
ROLL_LIMIT = 1e-4


def roll_invariance(device: str) -> dict[str, Any]:
    """Monostatic single bounce, the cross-section cannot change as the target rolls about
    the line of sight; analytic coverage once missed slivers between pixel centres and was
    8.6% high over 20 degrees of roll (``test_analytic_coverage_total_is_invariant_under_roll``).
    The device kernel at 48 px, 16 rolls."""
    from scipy.spatial.transform import Rotation

    roll = np.radians(np.arange(-30.0, 1.0, 2.0))
    att = (Rotation.from_euler("z", roll[:, None]) * Rotation.from_rotvec([0.5416, 0.3525, -0.4990])).as_matrix()
    sensor = pprender.Lidar(resolution=48, **ANALYTIC)
    s = pprender.render(body_panels(), sensor, att, outputs=("profile",), device=device).cross_section
    err = float(np.abs(s / s[-1, 0] - s[-1] / s[-1, 0]).max())
    row = {"rolls": len(roll), "error": err, "pass": err <= ROLL_LIMIT}
    print(f"  {row}", flush=True)
    return row


def scenes() -> list[tuple[str, pprender.Scene, dict[str, Any]]]:
    sphere = pprender.Scene(models.sphere(0.5, 4), materials.get("aluminium", alpha=0.3), smooth=True)
    plate = pprender.Scene(models.plate(0.6, 0.4, detail=2), materials.get("white_paint"))
    return [
        ("3U CubeSat, body panels, analytic coverage, Stokes (H)", body_panels(), ANALYTIC),
        ("smooth sphere, aluminium alpha 0.3, Mueller", sphere, {}),
        ("3U CubeSat, 4 materials, double bounce, Mueller", cubesat(), {}),
        ("plate, white paint, bistatic 0.2 rad, Stokes (H)", plate,
         {"bistatic_angle": 0.2, "polarization": [1.0, 1.0, 0.0, 0.0]}),
    ]


def _pixel_errors(a: np.ndarray, ref: np.ndarray, floor: float = 1e-2) -> np.ndarray:
    """Per pixel, the largest |a - ref| over the elements relative to the reference's
    intensity, on pixels above ``floor`` x the brightest."""
    i0 = ref[..., 0, 0] if ref.ndim == 5 else ref[..., 0]
    keep = i0 > floor * i0.max()
    d = np.abs(a - ref).reshape(i0.shape + (-1,))
    return d[keep].max(axis=-1) / i0[keep]


def _output(r: pprender.RenderResult, name: str) -> np.ndarray:
    """The output ``name`` of ``r``, which the render was asked for (so it is set)."""
    x = getattr(r, name)
    if x is None:
        raise RuntimeError(f"the render returned no {name!r} output although it was requested")
    return x


def _total_error(a: np.ndarray, ref: np.ndarray) -> float:
    """The largest |a - ref| of a cross-section's elements relative to the reference's S0
    (its intensity), the worst attitude."""
    n = len(ref)
    s0 = ref[:, 0, 0] if ref.ndim == 3 else ref[:, 0]
    return float((np.abs(a - ref).reshape(n, -1).max(axis=1) / s0).max())


def _profile_error(a: np.ndarray, ref: np.ndarray) -> float:
    """The profile's relative L1 error over bins and elements, the worst attitude."""
    n = len(ref)
    return float((np.abs(a - ref).reshape(n, -1).sum(axis=1) / np.abs(ref).reshape(n, -1).sum(axis=1)).max())


def agreement(device: str) -> tuple[list[dict[str, Any]], bool]:
    rows, ok = [], True
    q = random_quaternions(4, seed=2026)
    for name, scene, kw in scenes():
        mueller = kw.get("polarization") is None
        image = "mueller" if mueller else "stokes"
        out = ("profile", image, "range")
        r32 = pprender.render(scene, pprender.Lidar(resolution=96, pixel_samples=1, **kw), q, outputs=out,
                              device=device)
        r64 = pprender.render(scene, pprender.Lidar(resolution=96, pixel_samples=1, arithmetic="f64", **kw), q,
                              outputs=out)
        px = _pixel_errors(_output(r32, image), _output(r64, image))
        e = {
            "total": _total_error(r32.cross_section, r64.cross_section),
            "profile": _profile_error(_output(r32, "profile"), _output(r64, "profile")),
            "image_p99": float(np.percentile(px, 99)),
            "outliers": float(np.mean(px > OUTLIER)),
        }
        passed = all(e[k] <= LIMITS[k] for k in AGREEMENT)
        ok &= passed
        rows.append({"scene": name, **e, "pixels": int(px.size), "pass": passed})
        print(f"  {name}: total {e['total']:.2e}, profile {e['profile']:.2e}, pixels p99 {e['image_p99']:.2e}, "
              f"outliers {e['outliers']:.1e} of {px.size}: {'pass' if passed else 'FAIL'}", flush=True)
    return rows, ok


def _s0(profile: np.ndarray) -> np.ndarray:
    """A profile's S0: (N, B) of (N, B, 4, 4), (N, B, 4) or (N, B)."""
    return profile[..., 0, 0] if profile.ndim == 4 else profile[..., 0] if profile.ndim == 3 else profile


def area_errors(a: np.ndarray, ref: np.ndarray, profile: np.ndarray, ref_profile: np.ndarray,
                floor: float = 1e-2) -> dict[str, Any]:
    """Grade an illuminated area ``a`` (N, B) against the twin's ``ref``, with the profiles
    of the same renders, on the bins whose S0 is above ``floor`` x the attitude's peak.

    Returns the median and largest relative error of the area, the S0 profile's relative
    difference in the bin of the largest and over all bins, the bin that comes closest to
    its limit (``area_bin + area_tie`` x its S0 profile difference: ties move both), the
    profile's relative L1 error and ``pass``.
    """
    s0, ref_s0 = _s0(profile), _s0(ref_profile)
    keep = ref_s0 > floor * ref_s0.max(axis=1, keepdims=True)
    err = np.abs(a - ref)[keep] / ref[keep]
    perr = np.abs(s0 - ref_s0)[keep] / ref_s0[keep]
    limit = LIMITS["area_bin"] + LIMITS["area_tie"] * perr
    worst, largest = int(np.argmax(err / limit)), int(np.argmax(err))
    e = {
        "bins": int(keep.sum()),
        "median": float(np.median(err)),
        "max": float(err[largest]),
        "max_profile": float(perr[largest]),
        "profile_max": float(perr.max()),
        "worst": float(err[worst]),
        "worst_profile": float(perr[worst]),
        "worst_limit": float(limit[worst]),
        "profile": _profile_error(profile, ref_profile),
    }
    e["pass"] = bool(e["median"] <= LIMITS["area_median"] and e["worst"] <= e["worst_limit"]
                     and e["profile"] <= LIMITS["profile"])
    return e


def illuminated_area(device: str) -> dict[str, Any]:
    """The ``"illuminated_area"`` output of the CubeSat, device against twin (module
    docstring, 3): four attitudes (those of the hand check on an H200), 96x96."""
    q = random_quaternions(4, seed=7)
    out = ("profile", "illuminated_area")
    r32 = pprender.render(cubesat(), pprender.Lidar(resolution=96, pixel_samples=1), q, outputs=out, device=device)
    r64 = pprender.render(cubesat(), pprender.Lidar(resolution=96, pixel_samples=1, arithmetic="f64"), q,
                          outputs=out)
    e = area_errors(_output(r32, "illuminated_area"), _output(r64, "illuminated_area"), _output(r32, "profile"),
                    _output(r64, "profile"))
    print(f"  {e['bins']} bins: median {e['median']:.2e}, largest {e['max']:.2e} (S0 profile there "
          f"{e['max_profile']:.2e}, largest {e['profile_max']:.2e}); closest to its limit {e['worst']:.2e} "
          f"(limit {e['worst_limit']:.2e}); profile {e['profile']:.2e}: {'pass' if e['pass'] else 'FAIL'}",
          flush=True)
    return e


def surface_errors(a: np.ndarray, ref: np.ndarray, total: np.ndarray, ref_total: np.ndarray) -> dict[str, Any]:
    """Grade Mueller images ``a`` and cross-sections ``total`` against the twin's, as
    ``agreement`` does (``_pixel_errors``): the 99th percentile of the pixels' errors
    (``surface_p99``) and the total's (``surface_total``); the largest pixel error and the
    outlier fraction are shown, not graded (rasterizer ties on the facets' edges)."""
    px = _pixel_errors(a, ref)
    e = {"image_p99": float(np.percentile(px, 99)), "max": float(px.max()),
         "outliers": float(np.mean(px > OUTLIER)), "pixels": int(px.size),
         "total": _total_error(total, ref_total)}
    e["pass"] = bool(e["image_p99"] <= LIMITS["surface_p99"] and e["total"] <= LIMITS["surface_total"])
    return e


#: Rays of the path bank of ``surface_orders``' material: the agreement does not depend on
#: them (device and twin read the same tables), the build time does (about 3 s on 2 cores).
SURFACE_BANK_RAYS = 20_000


def surface_orders(device: str, once: dict[str, float]) -> list[dict[str, Any]]:
    """A sphere of a calibrated surface-orders material, device against twin, with
    ``brdf="shader"`` and ``"table"`` (module docstring, 4). The path bank is traced in
    memory (the disk cache is off for the build and restored after), its time in ``once``."""
    cache = pprender.cache_dir()
    pprender.set_cache_dir(None)
    try:
        t = time.perf_counter()
        mat = pprender.Material("beckmann", alpha=0.6, eta=complex(1.3763, 10.2449),
                                terms=("single", "double", "multiple"), orders="surface",
                                bank_rays=SURFACE_BANK_RAYS)
        once[f"surface-orders material: {SURFACE_BANK_RAYS:,}-ray path bank, calibration, tables (s)"] = (
            time.perf_counter() - t)
    finally:
        pprender.set_cache_dir(cache)
    scene = pprender.Scene(models.sphere(0.5, 5), mat)
    q = random_quaternions(4, seed=7)[:1]
    rows = []
    for brdf in ("shader", "table"):
        kw: dict[str, Any] = {"resolution": 96, "pixel_samples": 1, "brdf": brdf}
        out = ("profile", "mueller")
        a = pprender.render(scene, pprender.Lidar(**kw), q, outputs=out, device=device)
        b = pprender.render(scene, pprender.Lidar(arithmetic="f64", **kw), q, outputs=out)
        e = surface_errors(_output(a, "mueller"), _output(b, "mueller"), a.cross_section, b.cross_section)
        rows.append({"brdf": brdf, **e})
        print(f"  brdf={brdf}: pixels p99 {e['image_p99']:.2e} (largest {e['max']:.2e}, outliers "
              f"{e['outliers']:.1e} of {e['pixels']}), total {e['total']:.2e}: {'pass' if e['pass'] else 'FAIL'}",
              flush=True)
    return rows


#: Timed calls per measurement, after WARMUPS untimed ones. A GPU's clocks move between
#: calls of a few milliseconds (best of 3 read 16,000/s and 8,000/s for one request on two
#: H200 machines), so each rate is the best and the median of several.
REPEATS, WARMUPS = 7, 2


def _rate(scene: pprender.Scene, sensor: pprender.Lidar, outputs: tuple[str, ...], n: int,
          device: str) -> tuple[float, float]:
    """Realizations per second of ``n`` attitudes: (best, median) over REPEATS calls."""
    q = random_quaternions(n, seed=n)
    def once() -> None:
        pprender.render(scene, sensor, q, outputs=outputs, device=device)

    for _ in range(WARMUPS):
        once()
    best, median = best_time(once, REPEATS)
    return n / best, n / median


def _spin_up(scene: pprender.Scene, device: str, seconds: float = 2.0) -> None:
    """Keep the device busy for ``seconds`` so that its clocks are up before timing."""
    sensor, q = pprender.Lidar(resolution=RES, pixel_samples=1), random_quaternions(64, seed=3)
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end:
        pprender.render(scene, sensor, q, outputs=("profile", "mueller"), device=device)


def _best_call(scene: pprender.Scene, sensor: pprender.Lidar, q: np.ndarray, outputs: tuple[str, ...],
               device: str) -> tuple[float, dict[str, float]]:
    """The fastest of REPEATS calls (after WARMUPS) and its stages."""
    for _ in range(WARMUPS):
        pprender.render(scene, sensor, q, outputs=outputs, device=device)
    best, stages = np.inf, {}
    for _ in range(REPEATS):
        t = time.perf_counter()
        r = pprender.render(scene, sensor, q, outputs=outputs, device=device)
        dt = time.perf_counter() - t
        if dt < best:
            best, stages = dt, r.stage_seconds
    return best, stages


#: Batch size of the breakdown (section 6 of the module docstring).
BREAKDOWN_BATCH = 64
#: The stages shown in the breakdown, in order (``RenderResult.stage_seconds``).
STAGES = ("pipeline and buffers", "encode and submit", "device", "readback", "to NumPy")


def breakdown(device: str, batch: int = BREAKDOWN_BATCH) -> list[dict[str, Any]]:
    """Each output alone and together, Mueller, CubeSat at RES, ``batch`` attitudes:
    the rate and the stages of the best call (``_best_call``)."""
    scene, sensor = cubesat(), pprender.Lidar(resolution=RES, pixel_samples=1)
    q = random_quaternions(batch, seed=7)
    rows = []
    for outputs in (("profile",), ("mueller",), ("range",), ("profile", "mueller", "range")):
        best, stages = _best_call(scene, sensor, q, outputs, device)
        rows.append({"outputs": " + ".join(outputs), "batch": batch, "rate": batch / best, "seconds": best,
                     **{k: stages.get(k, 0.0) for k in STAGES}})
        print(f"  {rows[-1]}", flush=True)
    return rows


#: Batch size of the scaling rows (section 8 of the module docstring).
SCALING_BATCH = 256
#: Rays of each kind in the ray-casting rows (section 9; 2,000 with ``--quick``).
RAYCAST_RAYS = 1_000_000


def scaling(device: str, batch: int = SCALING_BATCH) -> list[dict[str, Any]]:
    """Profile-only Stokes (H) renders of ``batch`` attitudes: the CubeSat at several
    resolutions, and icospheres of 80 and 20,480 triangles at RES; the best call
    (``_best_call``) with its device time."""
    rough = pprender.Material("beckmann", alpha=0.3, eta=1.5)
    sat = cubesat()
    cases = [(f"3U CubeSat, {r}x{r}", sat, r) for r in (32, 64, 128, 256)]
    for k in (1, 5):
        mesh = models.sphere(0.5, k)
        cases.append((f"icosphere, {len(mesh.faces)} triangles, {RES}x{RES}", pprender.Scene(mesh, rough), RES))
    q = random_quaternions(batch, seed=11)
    rows = []
    for label, scene, res in cases:
        sensor = pprender.Lidar(resolution=res, pixel_samples=1, polarization=[1, 1, 0, 0])
        best, stages = _best_call(scene, sensor, q, ("profile",), device)
        rows.append({"case": label, "batch": batch, "rate": batch / best, "call_us": 1e6 * best / batch,
                     "device_us": 1e6 * stages.get("device", 0.0) / batch})
        print(f"  {rows[-1]}", flush=True)
    return rows


def throughput(device: str, budget: float, once: dict[str, float]) -> list[dict[str, Any]]:
    scene = cubesat()
    requests = [
        ("profile only (Stokes, H)", pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0]),
         ("profile",)),
        ("full model (Mueller profile + image + range)", pprender.Lidar(resolution=RES, pixel_samples=1),
         ("profile", "mueller", "range")),
    ]
    t = time.perf_counter()
    scene.prepare(0.0)
    once["BRDF tables of the CubeSat's materials (s; cached when the agreement built them)"] = (
        time.perf_counter() - t)
    t = time.perf_counter()
    pprender.render(scene, requests[1][1], random_quaternions(1, 0), outputs=requests[1][2], device=device)
    once["first render, shaders compiled (s)"] = time.perf_counter() - t
    rows = []
    if REPEATS > 1:  # (--quick times nothing worth spinning up for)
        _spin_up(scene, device)
    t_end = time.perf_counter() + budget
    for label, sensor, outputs in requests:
        n, prev, flat = 1, 0.0, 0
        while True:
            rate, median = _rate(scene, sensor, outputs, n, device)
            rows.append({"request": label, "batch": n, "rate": rate, "median": median})
            print(f"  {label}, batch {n}: {rate:.1f} /s (median {median:.1f})", flush=True)
            # the plateau: two doublings in a row that each add less than 10%
            flat = flat + 1 if n >= 16 and rate < 1.1 * prev else 0
            prev = max(prev, rate)
            # the next batch costs about twice this one's calls
            calls = REPEATS + WARMUPS
            if flat >= 2 or n >= 4096 or time.perf_counter() + 2 * calls * n / median > t_end:
                break
            n *= 2
    twin = pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0], arithmetic="f64")
    rate, median = _rate(scene, twin, ("profile",), 16, device)
    rows.append({"request": "profile only (Stokes, H), f64 CPU twin", "batch": 16, "rate": rate, "median": median})
    return rows


def report(info: dict[str, Any], agree: list[dict[str, Any]], speed: list[dict[str, Any]],
           parts: list[dict[str, Any]], scale: list[dict[str, Any]], once: dict[str, float], device: str,
           seconds: float, paths: list[str] | None = None, roll: dict[str, Any] | None = None,
           area: dict[str, Any] | None = None, surface: list[dict[str, Any]] | None = None,
           rays: list[dict[str, Any]] | None = None) -> str:
    lines = ["# GPU check", ""]
    if info.get("device_type") == "Cpu":
        lines += [
            f"> **Not a GPU run.** This page was written on {info.get('name')}, a CPU implementation of "
            "Vulkan, as a proof that the check runs; on a GPU machine: `scripts/gpu_bundle.sh` here, "
            "carry `.whl` and `.gl`, run `scripts/gpu_check.sh --write docs/gpu-benchmark.md` there "
            "(it overwrites this page), and commit the page.",
            "",
        ]
    lines += [
        "Written by `scripts/gpu_check.sh` (`scripts/gpu_check.py`); regenerate with it on the machine",
        "named below. What it checks and how is in the script's docstring.",
        "",
        f"- adapter: **{info.get('name')}** ({info.get('backend')}, {info.get('device_type')}), "
        f"driver {info.get('driver')} {info.get('driver_info', '')}".rstrip(),
        f"- requested device: `{device}`; pprender {pprender.__version__}; Python {platform.python_version()}; "
        f"numpy {np.__version__}; {os.cpu_count()} CPU threads ({platform.machine()})",
        f"- run time: {seconds:.0f} s",
        "",
        "## Agreement: f32 device kernel against the f64 CPU twin",
        "",
        "Four random attitudes, 96x96 pixels, one visibility sample per pixel, the balanced tables; "
        "pixels above 1% of the brightest. Limits: total and profile "
        f"{LIMITS['total']:g} (rasterizer ties move them), 99th-percentile pixel error {LIMITS['image_p99']:g}, "
        f"outlier pixels (error > {OUTLIER:g}) {LIMITS['outliers']:g} of the pixels. "
        "The analytic-coverage row takes exact pixel areas (2x2 sub-pixels) instead of samples.",
        "",
        "| scene | total (rel.) | profile (rel. L1) | pixel error, p99 | outlier pixels | pixels | result |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in agree:
        lines.append(f"| {r['scene']} | {r['total']:.2e} | {r['profile']:.2e} | {r['image_p99']:.2e} | "
                     f"{r['outliers']:.1e} | {r['pixels']} | {'pass' if r['pass'] else '**FAIL**'} |")
    if roll is not None:
        lines += [
            "",
            f"Roll invariance (`roll_invariance`): the body-panel CubeSat at 48 px, analytic coverage, "
            f"{roll['rolls']} rolls about the line of sight; the largest change of any Stokes component of the "
            f"cross-section relative to S0: {roll['error']:.1e} (limit {ROLL_LIMIT:g}): "
            f"{'pass' if roll['pass'] else '**FAIL**'}.",
        ]
    if area is not None:
        lines += [
            "",
            "## Illuminated area: f32 device kernel against the f64 CPU twin",
            "",
            "The `\"illuminated_area\"` output of the 3U CubeSat (4 materials), four attitudes, 96x96 pixels, one "
            "sample per pixel; the range bins above 1% of each attitude's peak S0, relative errors. Rasterizer "
            "ties move a bin's S0 profile and its area together, so the S0 profile's difference is shown beside "
            f"the area's. Limits: median {LIMITS['area_median']:g}; each bin {LIMITS['area_bin']:g} + "
            f"{LIMITS['area_tie']:g} x its S0 profile difference (the row shows the bin closest to its limit); "
            f"the profile's relative L1 error {LIMITS['profile']:g}.",
            "",
            "| bins | median | largest | S0 profile in that bin | S0 profile, largest | closest to its limit "
            "| its limit | profile (rel. L1) | result |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---|",
            f"| {area['bins']} | {area['median']:.2e} | {area['max']:.2e} | {area['max_profile']:.2e} | "
            f"{area['profile_max']:.2e} | {area['worst']:.2e} | {area['worst_limit']:.2e} | {area['profile']:.2e} | "
            f"{'pass' if area['pass'] else '**FAIL**'} |",
        ]
    if surface:
        lines += [
            "",
            "## Surface orders (calibrated single term): f32 device kernel against the f64 CPU twin",
            "",
            "A faceted sphere (icosphere, 5 subdivisions) of `Material(\"beckmann\", alpha=0.6, "
            "eta=1.3763+10.2449j, terms=(\"single\", \"double\", \"multiple\"), orders=\"surface\", "
            f"bank_rays={SURFACE_BANK_RAYS})`: the single term's masking calibrated to the traced surface, a table "
            "the kernel reads. One attitude, 96x96, Mueller; pixels above 1% of the brightest, graded as the "
            f"agreement's. Limits: 99th-percentile pixel error {LIMITS['surface_p99']:g}, total "
            f"{LIMITS['surface_total']:g}; the largest pixel error and the outliers (error > {OUTLIER:g}: ties on "
            "the facets' edges) are shown, not graded.",
            "",
            "| brdf | pixel error, p99 | largest | outlier pixels | pixels | total (rel.) | result |",
            "|---|---:|---:|---:|---:|---:|---|",
        ]
        for r in surface:
            lines.append(f"| `{r['brdf']}` | {r['image_p99']:.2e} | {r['max']:.2e} | {r['outliers']:.1e} | "
                         f"{r['pixels']} | {r['total']:.2e} | {'pass' if r['pass'] else '**FAIL**'} |")
    lines += [
        "",
        f"## Throughput: 3U CubeSat, {RES}x{RES}, one sample per pixel",
        "",
        f"Realizations (attitudes) per second, batch / best and batch / median of {REPEATS} calls after "
        f"{WARMUPS} warm-up calls.",
        "",
        "| request | batch | realizations/s, best | median |",
        "|---|---:|---:|---:|",
    ]
    for r in speed:
        lines.append(f"| {r['request']} | {r['batch']} | {r['rate']:.1f} | {r['median']:.1f} |")
    lines += [
        "",
        f"## Where the time goes: Mueller outputs, batch {parts[0]['batch'] if parts else BREAKDOWN_BATCH}",
        "",
        f"The best of {REPEATS} calls after {WARMUPS} warm-up calls, and that call's stages (ms; "
        "`RenderResult.stage_seconds`): *pipeline and buffers* is making the call's device buffers, "
        "*device* is the wait for the GPU after submitting, *readback* "
        "mapping the result buffers and decoding them on the host, *to NumPy* making the arrays. "
        "The rest of the call (planning, bind groups, Python checks) is the difference.",
        "",
        "| outputs | realizations/s | call (ms) | " + " | ".join(f"{k} (ms)" for k in STAGES) + " |",
        "|---|---:|---:|" + "---:|" * len(STAGES),
    ]
    for r in parts:
        lines.append(f"| {r['outputs']} | {r['rate']:.1f} | {1e3 * r['seconds']:.1f} | "
                     + " | ".join(f"{1e3 * r[k]:.1f}" for k in STAGES) + " |")
    if paths:
        lines += ["", "## Inter-reflections: the first hits on the device, the paths on the CPU", "",
                  "The render benchmark's table (`benchmarks/bench_render.py`; its docstring says how the noise "
                  f"is measured), run here on {os.cpu_count()} CPU threads.", ""]
        lines += paths[:-1] if paths[-1] == "" else paths
    lines += [
        "",
        "## What the device time scales with: profile only (Stokes, H), "
        f"batch {scale[0]['batch'] if scale else SCALING_BATCH}",
        "",
        f"The best of {REPEATS} calls after {WARMUPS} warm-up calls: the call's time and the device's "
        "(the *device* stage) "
        "per attitude. Device time that stays put as pixels and triangles grow is per-attitude overhead.",
        "",
        "| scene | realizations/s | call per attitude (us) | device per attitude (us) |",
        "|---|---:|---:|---:|",
    ]
    for r in scale:
        lines.append(f"| {r['case']} | {r['rate']:.1f} | {r['call_us']:.1f} | {r['device_us']:.1f} |")
    if rays:
        lines += ["", "## Ray casting: the renderer's tree walked in the kernel and on the CPU", "",
                  "The ray-casting benchmark (`benchmarks/bench_raycast.py`; its docstring says what the rays "
                  f"are and what the columns mean), run here: `f64` on {os.cpu_count()} CPU threads, the "
                  "kernel on the device, Embree (one thread) where embreex is installed.", ""]
        lines += bench_raycast.table(rays) + [""] + bench_raycast.summary(rays)
    lines += ["", "One-off costs:", ""]
    lines += [f"- {k}: {v:.3f}" for k, v in once.items()]
    lines += ["", "Adapter limits:", ""]
    lines += [f"- {k}: {v}" for k, v in sorted(info.items()) if k not in ("name", "backend", "device_type", "driver",
                                                                            "driver_info")]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="gpu", choices=("gpu", "cpu", "auto"))
    ap.add_argument("--write", default=None, help="write the markdown report here")
    ap.add_argument("--budget", type=float, default=240.0, help="seconds for the throughput sweep")
    ap.add_argument("--quick", action="store_true",
                    help="batches of 4 in the breakdown and scaling sections, one call per measurement and "
                         "no warm-up (a test that they run, not a measurement)")
    a = ap.parse_args(argv)
    global REPEATS, WARMUPS
    REPEATS, WARMUPS = (1, 0) if a.quick else (7, 2)
    t0 = time.perf_counter()
    print(f"pprender {pprender.__version__} from {pprender.__file__}", flush=True)
    t = time.perf_counter()
    try:
        info = pprender.device_info(a.device)
    except pprender.Error as e:
        print(f"no {a.device} device: {e}", file=sys.stderr)
        return 2
    once = {"device creation (s)": time.perf_counter() - t}
    print("device_info:", info, flush=True)
    print("agreement (f32 device kernel vs f64 CPU twin):", flush=True)
    agree, ok = agreement(a.device)
    print("roll invariance (analytic coverage):", flush=True)
    roll = roll_invariance(a.device)
    ok &= roll["pass"]
    print("illuminated area (f32 device kernel vs f64 CPU twin):", flush=True)
    area = illuminated_area(a.device)
    ok &= area["pass"]
    print("surface orders, calibrated single term (f32 device kernel vs f64 CPU twin):", flush=True)
    surface = surface_orders(a.device, once)
    ok &= all(r["pass"] for r in surface)
    print("throughput:", flush=True)
    speed = throughput(a.device, a.budget, once)
    print("breakdown:", flush=True)
    parts = breakdown(a.device, 4 if a.quick else BREAKDOWN_BATCH)
    print("scaling:", flush=True)
    scale = scaling(a.device, 4 if a.quick else SCALING_BATCH)
    paths = None
    if not a.quick:
        print("inter-reflections:", flush=True)
        paths = interreflection_rows(a.device, 3)
    print("ray casting:", flush=True)
    rays = (bench_raycast.measure([a.device], 2000, 1, bench_raycast.MESHES[:1]) if a.quick
            else bench_raycast.measure([a.device], RAYCAST_RAYS, 3))
    text = report(info, agree, speed, parts, scale, once, a.device, time.perf_counter() - t0, paths, roll,
                  area, surface, rays)
    print(text)
    if a.write:
        with open(a.write, "w") as f:
            f.write(text)
        print(f"wrote {a.write}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
