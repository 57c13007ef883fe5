"""Where the light goes: a cavity's energy balance and a trihedral's triple-bounce power.

Two checks of the inter-reflections (``bounces`` 2 and 3) against results they were not
made from, by integrating pprender's bistatic cross-section of each bounce order over the
receiver's directions (the transmitter fixed):

    P_k / E = (1 / 4 pi) * integral of sigma_k(r) over the receiver directions r,

``P_k`` the power that leaves after ``k`` reflections, ``E`` the irradiance (W m^-2 across
the beam), ``sigma_k`` the lidar cross-section of that order (m^2; 4 pi times the radiant
intensity over the irradiance). Both use perfectly reflecting surfaces
(``pprender.white_furnace``: F = 1, Beckmann single + multiple terms with albedo 1 within
1e-4, tests/test_energy.py), so no light is absorbed.

The independent reference is :func:`rough_mirror_trace`, an explicit simulation of rough
mirrors in geometric optics (numpy; rays reflected about Beckmann microfacet normals drawn
from the distribution of visible normals, up to 6 reflections): it knows nothing of
pprender's BRDF tables, path sampling, multiple importance sampling or bistatic renders,
and it counts every order, including those beyond pprender's three. It leaves out the
microsurface's masking of the reflected ray, and so the multiple term to which pprender's
model hands that light (``1 - E``, E the single term's albedo), so the two models part where
that matters: at large alpha and grazing angles (the first table prints ``1 - E`` at 45 deg,
the walls' incidence).

1. **A cavity** (:func:`cone_pit`: a pit with 45 deg walls, a 64-sided pyramid of
   single-sided inner faces, lit along its axis). Everything that enters the pit leaves
   it through its opening, upward, so the powers of all orders sum to ``E`` times the
   opening's area. With mirror walls every ray reflects exactly twice (down, across the
   axis, up); the roughness spreads the light over the orders. pprender's orders 1-3 plus
   the simulation's orders 4 and more must sum to 1 (returned plus escaped light equals
   the incident), and each order must match the simulation's.
2. **A square trihedral** against its analytic effective area
   (``benchmarks/mitsuba_corners.py``: ``A_eff = area(H cap -H)``, the projected aperture
   intersected with its point reflection, checked there against a brute-force specular
   ray trace). As the roughness goes to 0 every ray entering ``A_eff`` leaves after three
   reflections, and only those: ``P_3 / E -> A_eff``. The roughness moves rays across
   ``A_eff``'s boundary, a loss first order in alpha, largest on the axis, where ``A_eff``
   is the whole aperture and rays can only leave it (the simulation gives it
   independently). The table also gives pprender's linear extrapolation to alpha = 0,
   ``2 r(alpha) - r(2 alpha)``.

Quadrature: the attitude ``R = Ry(beta) Rz(phi) R_view`` keeps the transmitter fixed in the
body frame (``R^T (sin beta, 0, cos beta) = R_view^T Z``) and puts the receiver at the polar
angle ``beta`` (pprender's bistatic angle) and azimuth ``phi`` about it. Gauss-Legendre in
``beta`` over segments scaled to the lobes, the trapezoid rule in ``phi`` (periodic: exact
for harmonics below ``n_phi``), weight ``sin(beta)``. pprender's bistatic angle is below
pi/2, so the receivers cover the hemisphere about the transmitter; both set-ups send
nothing beyond it (the pit's light leaves upward through its opening; the trihedral's
triple bounce is retro-reflected within a few alpha, and the window reaches 12 alpha).

Noise: pprender's powers are means over path seeds (``path_seed``) +- the standard deviation
of that mean; the simulation's +- its counting (Poisson) error.

    python scripts/corner_energy.py [--write] [--quick]

``--write`` writes docs/corner-energy.md; ``--quick`` runs a smaller version (about the
tests' sizes).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import mitsuba_corners as mc  # noqa: E402  (the trihedral, its attitudes and effective area)

import pprender  # noqa: E402

#: Diffuse view factor of a 45 deg cone's inner wall to itself: 1 - sin(45 deg) (the wall
#: sees the opening with F = A_opening / A_wall = sin of the half-angle, by reciprocity).
CONE_SELF_VIEW = 1.0 - math.sin(math.radians(45.0))


def cone_pit(radius: float = 0.3, wall_deg: float = 45.0, sides: int = 64) -> trimesh.Trimesh:
    """A pit: the inside of a cone with its apex at the body origin, axis ``+z``, walls at
    ``wall_deg`` to the opening's plane, ``sides`` triangles (an even number: opposite
    walls are parallel, so a mirror pit reflects every ray exactly twice at 45 deg).
    Single-sided: the front faces (normals up and toward the axis) are the inner ones."""
    if sides % 2:
        raise ValueError("sides must be even")
    h = radius * math.tan(math.radians(wall_deg))
    ang = 2.0 * math.pi * np.arange(sides) / sides
    rim = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full(sides, h)], axis=1)
    vertices = np.vstack([np.zeros((1, 3)), rim])
    faces = np.array([[0, 1 + k, 1 + (k + 1) % sides] for k in range(sides)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    radial = mesh.triangles_center * np.array([1.0, 1.0, 0.0])
    assert np.all(mesh.face_normals[:, 2] > 0) and np.all(np.einsum("ij,ij->i", mesh.face_normals, radial) < 0)
    return mesh


def opening_area(mesh: trimesh.Trimesh, direction: Sequence[float]) -> float:
    """Projected area (m^2) along ``direction`` of the faces turned toward it: the area
    through which the beam enters."""
    cos = mesh.face_normals @ np.asarray(direction, dtype=np.float64)
    return float(np.sum(np.clip(cos, 0.0, None) * mesh.area_faces))


def _ry(b: float) -> np.ndarray:
    return np.array([[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0], [-math.sin(b), 0.0, math.cos(b)]])


def _rz(p: float) -> np.ndarray:
    return np.array([[math.cos(p), -math.sin(p), 0.0], [math.sin(p), math.cos(p), 0.0], [0.0, 0.0, 1.0]])


def receiver_attitudes(view: np.ndarray, beta: float, n_phi: int) -> np.ndarray:
    """``(n_phi, 3, 3)`` attitudes with the transmitter along ``view``'s line of sight
    (``view^T Z`` in the body frame) and the receiver ``beta`` from it, at azimuths
    ``2 pi (j + 1/2) / n_phi`` about it."""
    return np.stack([_ry(beta) @ _rz(2.0 * math.pi * (j + 0.5) / n_phi) @ view for j in range(n_phi)])


def order_powers(mesh: trimesh.Trimesh, material: pprender.Material, view: np.ndarray, beta_edges: Sequence[float],
                 nodes: int, n_phi: int, resolution: int, path_samples: int, seed: int,
                 bounces: int = 3) -> np.ndarray:
    """``P_k / E`` (m^2) for ``k = 1, 2, 3``: the bistatic cross-section of each order
    integrated over the receiver directions with ``beta`` in ``[beta_edges[0],
    beta_edges[-1]]`` (Gauss-Legendre, ``nodes`` per segment) and all azimuths
    (``n_phi``), divided by 4 pi. Each ``beta`` renders with its own path seed,
    ``1000 seed + node``, so that the paths' errors average out over the nodes (one seed for
    all would reuse the same points in every render). Analytic pixel coverage: the one-bounce
    part has no sampling error (with 8 samples per pixel the pit's 64-sided rim moves
    order 1 by up to 0.5% between resolutions). ``bounces=2`` leaves order 3 at 0 (for a
    cavity that keeps almost none of it: cheaper)."""
    scene = pprender.Scene(mesh, material)
    x, w = np.polynomial.legendre.leggauss(nodes)
    total = np.zeros(3)
    node = 0
    for a, b in zip(beta_edges[:-1], beta_edges[1:]):
        for beta, wb in zip(0.5 * (b - a) * x + 0.5 * (a + b), 0.5 * (b - a) * w):
            node += 1
            lidar = pprender.Lidar(resolution=resolution, bounces=bounces, path_samples=path_samples,
                                   path_seed=1000 * seed + node,
                                   bistatic_angle=float(beta), polarization=[1, 0, 0, 0], arithmetic="f64",
                                   coverage="analytic")
            r = pprender.render(scene, lidar, receiver_attitudes(view, float(beta), n_phi), outputs=("profile",))
            sigma = r.by_bounce["cross_section"][..., 0]  # (phi, order) S0 in m^2
            total[:bounces] += wb * math.sin(beta) * (2.0 * math.pi / n_phi) * sigma.sum(axis=0)
    return total / (4.0 * math.pi)


def rough_mirror_trace(mesh: trimesh.Trimesh, direction: Sequence[float], alpha: float, rays: int, seed: int,
                       max_reflections: int = 4, chunk: int = 100_000) -> np.ndarray:
    """An explicit simulation of F = 1 rough mirrors in geometric optics, independent of
    pprender: rays jittered on a grid over the square ``[-ext, ext]^2`` across ``direction`` (body
    frame, toward the source) enter along ``-direction``; at each hit the ray reflects
    about a microfacet normal ``m`` drawn from the Beckmann distribution of visible normals
    (slopes Gaussian with variance ``alpha^2 / 2`` per axis, i.e. ``D(m) cos(theta_m)``,
    accepted in proportion to ``max(0, -k . m) / cos(theta_m)``),
    and goes on; a reflection below the plate (``k' . n <= 0``) is drawn again. The
    masking of the reflected ray by the microsurface is left out (``1 - G1`` below 1e-6 at
    alpha 0.1 and 60 deg from the normal). Returns ``P_k / E`` (m^2) for ``k = 1 ..
    max_reflections`` reflections, and last the rays still inside after
    ``max_reflections``. Uses ``mitsuba_corners``' brute-force ray-triangle intersection."""
    rng = np.random.default_rng(seed)
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    tris = np.asarray(mesh.triangles, dtype=np.float64)
    fn = np.asarray(mesh.face_normals, dtype=np.float64)
    ext = mc.extent(mesh)
    u, v = mc._plane_basis(d)
    counts = np.zeros(max_reflections + 1)
    eps = 1e-9 * ext
    side = int(math.ceil(math.sqrt(rays)))
    rays = side * side
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), axis=-1).reshape(-1, 2)
    done = 0
    while done < rays:
        m = min(chunk, rays - done)
        xy = -ext + (cells[done:done + m] + rng.uniform(0.0, 1.0, (m, 2))) * (2.0 * ext / side)
        o = xy[:, :1] * u + xy[:, 1:] * v + 2.0 * ext * d
        k = np.broadcast_to(-d, (m, 3)).copy()
        alive = np.arange(m)
        for b in range(max_reflections + 1):
            t, idx = mc._intersect(o[alive], k[alive], tris, eps)
            hit = np.isfinite(t)
            if b > 0:
                counts[b - 1] += np.count_nonzero(~hit)
            alive, t, idx = alive[hit], t[hit], idx[hit]
            if b == max_reflections or len(alive) == 0:
                counts[max_reflections] += len(alive)
                break
            n = fn[idx]
            kk = k[alive]
            cos_i = -np.einsum("ij,ij->i", kk, n)
            if np.any(cos_i <= 0.0):
                raise RuntimeError("a ray reached the back of a single-sided plate")
            t1, t2 = mc._batch_basis(n)  # (a tangent basis at each hit)
            out = np.zeros_like(kk)
            bound = cos_i + np.sqrt(1.0 - cos_i**2) * 6.0 * alpha / math.sqrt(2.0)
            todo = np.arange(len(alive))
            while len(todo):
                s = rng.normal(0.0, alpha / math.sqrt(2.0), (len(todo), 2))
                mf = n[todo] - s[:, :1] * t1[todo] - s[:, 1:] * t2[todo]
                mf /= np.linalg.norm(mf, axis=1, keepdims=True)
                km = np.einsum("ij,ij->i", kk[todo], mf)
                # accept with max(0, -k . m) / cos(theta_m) = cos_i + sin_i (slope toward k) over its bound
                # for slopes below 6 standard deviations (beyond: probability 1e-9, refused)
                ratio = np.maximum(0.0, -km) / (np.einsum("ij,ij->i", mf, n[todo]) * bound[todo])
                if np.any(ratio > 1.0):
                    raise RuntimeError(f"visible-normal acceptance ratio {ratio.max()} above 1")
                wr = kk[todo] - 2.0 * km[:, None] * mf
                ok = (rng.uniform(0.0, 1.0, len(todo)) < ratio) & (np.einsum("ij,ij->i", wr, n[todo]) > 0.0)
                out[todo[ok]] = wr[ok]
                todo = todo[~ok]
            o[alive] = o[alive] + t[:, None] * kk
            k[alive] = out
        done += m
    return counts * (2.0 * ext) ** 2 / rays


def white(alpha: float) -> pprender.Material:
    """F = 1 Beckmann with its energy-conserving multiple term (albedo 1)."""
    return pprender.white_furnace("beckmann", alpha=alpha, terms=("single", "multiple"))


def cavity(alpha: float, seeds: Sequence[int], quick: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The pit's orders 1-3 as fractions of the power entering it: mean and standard
    deviation of the mean over ``seeds``. Quadrature nodes finer near the retro-reflected
    lobe (order 2 leaves along the axis); doubling the segments moves the orders by under
    5e-4 (alpha 0.2)."""
    mesh = cone_pit()
    view = np.eye(3)
    edges = [0.0, 0.1, 0.2, 0.4, 0.8, 1.2, math.pi / 2]
    nodes, n_phi, res, paths = (6, 4, 40, 16) if quick else (8, 4, 64, 32)
    runs = np.array([order_powers(mesh, white(alpha), view, edges, nodes, n_phi, res, paths, s) for s in seeds])
    runs /= opening_area(mesh, view[2])
    return runs.mean(axis=0), runs.std(axis=0, ddof=1) / math.sqrt(len(seeds)) if len(seeds) > 1 else np.zeros(3)


def trihedral_ratio(alpha: float, off_axis_deg: float, seeds: Sequence[int], quick: bool = False) -> tuple[float, float]:
    """``P_3 / (E A_eff)`` for the F = 1 trihedral seen ``off_axis_deg`` from its axis:
    mean and standard deviation of the mean over ``seeds``. The receivers reach 12 alpha
    from the transmitter (the triple bounce's lobe is a few alpha wide)."""
    mesh = mc.trihedral()
    view = mc.trihedral_rotation(off_axis_deg)
    a_eff = mc.trihedral_effective_area(0.3, view[2]).area
    edges = 2.0 * alpha * np.array([0.0, 0.5, 1.0, 2.0, 3.0, 4.5, 6.0])
    nodes, n_phi, res, paths = (4, 8, 40, 16) if quick else (6, 8, 48, 32)
    r = np.array([order_powers(mesh, white(alpha), view, edges, nodes, n_phi, res, paths, s)[2] / a_eff
                  for s in seeds])
    return float(r.mean()), float(r.std(ddof=1) / math.sqrt(len(seeds))) if len(seeds) > 1 else 0.0


def simulated(mesh: trimesh.Trimesh, direction: Sequence[float], alpha: float, rays: int,
              seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rough_mirror_trace` with up to 6 reflections: ``P_k / E`` for ``k = 1..6``
    and beyond, and their Poisson errors (the square of a ray's cell area times its count)."""
    p = rough_mirror_trace(mesh, direction, alpha, rays, seed, max_reflections=6)
    side = int(math.ceil(math.sqrt(rays)))
    cell = (2.0 * mc.extent(mesh) / side) ** 2
    return p, np.sqrt(p * cell)


def main(quick: bool = False) -> str:
    t0 = time.time()
    seeds = (0, 1) if quick else (0, 1, 2, 3)
    rays = 250_000 if quick else 4_000_000
    lines = [
        "# Where the light goes: a cavity's energy balance, a trihedral's effective area",
        "",
        "Written by `python scripts/corner_energy.py --write` (its docstring derives both checks, "
        "the quadrature and the explicit simulation). pprender's bistatic cross-section of each "
        "bounce order, integrated over the receiver's directions, is the power that leaves after "
        "that many reflections; f64 CPU renders with `bounces=3`, each value the mean over path "
        f"seeds {list(seeds)} (+- the standard deviation of that mean). `simulated`: an explicit "
        f"numpy simulation of the same rough mirrors ({rays:,} rays, up to 6 reflections, +- its "
        "counting error). Perfectly reflecting surfaces (`white_furnace` Beckmann with its multiple "
        "term, albedo 1).",
        "",
        "## 1. A pit: returned plus escaped light equals the incident",
        "",
        "A pit with 45 deg walls (64 sides, 0.3 m radius) lit along its axis. Power leaving after "
        "k reflections as a fraction of the power entering the opening. With mirror walls every ray "
        "reflects twice; everything that enters leaves through the opening, so pprender's orders "
        "1-3 plus the simulation's orders 4 and more must make 1. The simulation leaves out the "
        "microsurface's masking of reflected rays, which pprender's model hands to its multiple "
        "term, a broad lobe: `1 - E(45 deg)` is that share of the light at the walls' incidence "
        "(`pprender.albedo` of the single term). Where it is not small the two models split the "
        "light over the orders differently, and the last column mixes them.",
        "",
        "| alpha | 1 - E(45 deg) | | order 1 | order 2 | order 3 | orders 4+ | pprender 1-3 + simulated 4+ |",
        "|---|---|---|---|---|---|---|---|",
    ]
    mesh = cone_pit()
    area = opening_area(mesh, (0.0, 0.0, 1.0))
    for alpha in ((0.1, 0.2) if quick else (0.05, 0.1, 0.2, 0.4)):
        mean, sd = cavity(alpha, seeds, quick)
        sim, sim_sd = (x / area for x in simulated(mesh, (0.0, 0.0, 1.0), alpha, rays))
        beyond, beyond_sd = sim[3:].sum(), math.sqrt(float(np.sum(sim_sd[3:] ** 2)))
        total = mean.sum() + beyond
        total_sd = math.sqrt(float(np.sum(sd**2)) + beyond_sd**2)
        single = pprender.white_furnace("beckmann", alpha=alpha, terms=("single",))
        masked = 1.0 - float(pprender.albedo(single, np.array([[math.sqrt(0.5), 0.0, math.sqrt(0.5)]]))[0])
        lines.append(f"| {alpha} | {masked:.1e} | pprender | {mean[0]:.4f} | {mean[1]:.4f} +- {sd[1]:.4f} | "
                     f"{mean[2]:.2e} +- {sd[2]:.0e} | | {total:.4f} +- {total_sd:.4f} |")
        lines.append(f"| | | simulated | {sim[0]:.4f} +- {sim_sd[0]:.4f} | {sim[1]:.4f} +- {sim_sd[1]:.4f} | "
                     f"{sim[2]:.2e} +- {sim_sd[2]:.0e} | {beyond:.2e} +- {beyond_sd:.0e} | {sim.sum():.4f} |")
        print(*lines[-2:], sep="\n", flush=True)
    lines += [
        "",
        "## 2. The square trihedral's triple bounce against its effective area",
        "",
        "0.3 m square trihedral seen 0, 10 and 20 deg off its axis; ratio = power leaving after 3 "
        "reflections / (irradiance x analytic A_eff). It must tend to 1 as alpha goes to 0. The "
        "roughness takes rays across A_eff's boundary, a loss first order in alpha, largest on the "
        "axis, where A_eff is the whole aperture and rays can only leave it. `extrapolated`: "
        "pprender's `2 r(alpha) - r(2 alpha)`.",
        "",
        "| off axis | A_eff (m^2) | alpha | pprender ratio | simulated ratio | pprender extrapolated to 0 |",
        "|---|---|---|---|---|---|",
    ]
    tri = mc.trihedral()
    alphas = (0.01, 0.02) if quick else (0.01, 0.02, 0.05, 0.1)
    for off in (0.0, 10.0, 20.0):
        d = mc.trihedral_direction(off)
        a_eff = mc.trihedral_effective_area(0.3, d).area
        res = {a: trihedral_ratio(a, off, seeds, quick) for a in alphas}
        for a in alphas:
            m, sd = res[a]
            sim, sim_sd = simulated(tri, d, a, rays)
            ext = ""
            if a == alphas[0]:  # (at larger alpha the ratio is not linear over [alpha, 2 alpha])
                m2, sd2 = res[2 * a]
                ext = f"{2 * m - m2:.4f} +- {math.hypot(2 * sd, sd2):.4f}"
            lines.append(f"| {off:g} deg | {a_eff:.5f} | {a} | {m:.4f} +- {sd:.4f} | "
                         f"{sim[2] / a_eff:.4f} +- {sim_sd[2] / a_eff:.4f} | {ext} |")
            print(lines[-1], flush=True)
    lines += ["", f"pprender {pprender.__version__}, {time.time() - t0:.0f} s.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    text = main(quick="--quick" in sys.argv)
    if "--write" in sys.argv:
        (ROOT / "docs" / "corner-energy.md").write_text(text)
        print("wrote docs/corner-energy.md")
