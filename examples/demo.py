"""The main job (``make demo``): a 3U CubeSat rendered as PPR sees it, plus BRDF plots.

Writes PNG figures to ``out/`` (or the directory given as the first argument) and prints
their paths:

* ``cubesat_images.png``: for a few attitudes of the default 3U CubeSat (aluminium bus,
  glass-covered solar cells, white-painted panel backs), monostatic at 1064 nm with a
  100 ps pulse: the total cross-section per pixel (M00), the degree of polarization of the
  return for horizontally polarized transmission, and the depolarization index of each
  pixel's Mueller matrix (the seed's Figure 9 analogue). Light reflected between parts
  (up to 3 bounces: a panel against the bus is a corner) is included. The materials are
  :mod:`pprender.materials`' defaults: the aluminium and the cover glass (alpha 0.05-0.3)
  take their orders >= 2 from path banks traced on explicit surfaces
  (``orders="surface"``); on a machine without them in its cache the first run traces
  them (alpha 0.05, 0.15 and 0.3: about 2 minutes on 2 cores, with a progress line),
  later runs read them.
* ``cubesat_profiles.png``: the range-resolved returns of the same attitudes: M00 and the
  co- and cross-polarized returns for horizontal linear and for circular transmission, and
  the part of M00 that reached the receiver after 2 or 3 reflections. Each panel has its
  own y scale (the 0 deg glint is 100x the others).
* ``cubesat_range.png``: the range maps of the same attitudes (:func:`pprender.plot.range_image`).
* For each named material: the 16 Mueller elements (normalized by M00) and M00 against
  the scattering geometry, in monostatic backscatter and in the plane of incidence at 30
  degrees incidence, plus depolarization and diattenuation of the backscattered return.
"""

from __future__ import annotations

import sys
import time
from typing import Any
from pathlib import Path

import numpy as np

import pprender
from pprender import materials, plot, polarimetry

NAMES = ("aluminium", "gold", "fused_silica", "kapton", "white_paint")


def _sph(theta: np.ndarray, phi: float = 0.0) -> np.ndarray:
    return np.stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1
    )


def cubesat_demo(out: Path) -> list[Path]:
    """Render the default 3U CubeSat at four attitudes; write the images and profiles."""
    import matplotlib.pyplot as plt

    from pprender import models

    mesh = models.cubesat("3U")
    mats = {
        "bus": materials.get("aluminium", alpha=0.15),
        "solar_cells": materials.get("fused_silica", alpha=0.05),
        "panel_back": materials.get("white_paint"),
        "antenna": materials.get("aluminium", alpha=0.3),
    }
    scene = pprender.Scene(mesh, {p: mats[p] for p in mesh.metadata["pprender_parts"]})
    # bounces=3: light reflected between parts too (docs/interreflections.md)
    sensor = pprender.Lidar(wavelength=1064e-9, pulse_fwhm=100e-12, bounces=3)
    # attitudes: (w, x, y, z) quaternions, rotations about a tilted axis
    angles = np.radians([0.0, 30.0, 60.0, 100.0])
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    q = np.concatenate([np.cos(angles / 2)[:, None], np.sin(angles / 2)[:, None] * axis], axis=1)
    t0 = time.perf_counter()
    res = pprender.render(scene, sensor, q, outputs=("profile", "mueller", "range"))
    dt = time.perf_counter() - t0
    print(
        f"rendered {len(q)} attitudes of a {scene.n_faces}-triangle 3U CubeSat at "
        f"{res.coverage.shape[1] if res.coverage is not None else '?'} px square in {dt:.2f} s on {res.device} "
        f"(tables {res.table_seconds:.2f} s)"
    )
    assert res.mueller is not None and res.profile is not None
    M = res.mueller
    m00 = M[..., 0, 0]
    s_out = M @ np.array([1.0, 1.0, 0.0, 0.0])  # horizontal linear transmitted
    with np.errstate(invalid="ignore", divide="ignore"):
        dop = np.where(m00 > 0, polarimetry.dop(s_out), np.nan)
        dep = np.where(m00 > 0, polarimetry.depolarization_index(M), np.nan)
    ext = res.extent
    box = (-ext, ext, -ext, ext)
    fig, axes = plt.subplots(3, len(q), figsize=(3.6 * len(q), 10), constrained_layout=True)
    vmax = np.nanmax(m00)
    for k in range(len(q)):
        im0 = axes[0, k].imshow(
            np.log10(np.where(m00[k] > 0, m00[k], np.nan)), extent=box,
            vmin=np.log10(vmax) - 6, vmax=np.log10(vmax), cmap="magma",
        )
        axes[0, k].set_title(f"{np.degrees(angles[k]):.0f} deg: log10 dsigma (m^2)")
        im1 = axes[1, k].imshow(dop[k], extent=box, vmin=0, vmax=1, cmap="viridis")
        axes[1, k].set_title("DoP, horizontal transmit")
        im2 = axes[2, k].imshow(dep[k], extent=box, vmin=0, vmax=1, cmap="viridis")
        axes[2, k].set_title("depolarization index")
    fig.colorbar(im0, ax=axes[0, :].tolist(), shrink=0.8)
    fig.colorbar(im1, ax=axes[1, :].tolist(), shrink=0.8)
    fig.colorbar(im2, ax=axes[2, :].tolist(), shrink=0.8)
    for ax in axes.flat:
        ax.set_xlabel("X (m)")
        ax.set_ylabel("Y (m)")
    fig.suptitle(
        "3U CubeSat, monostatic, 1064 nm, 100 ps: cross-section, degree of polarization, "
        "depolarization (sensor looks along -Z)"
    )
    p1 = out / "cubesat_images.png"
    fig.savefig(p1, dpi=80)
    plt.close(fig)

    # profiles: M00 and co/cross channels for linear (H) and circular transmit
    P = res.profile
    t_ns = res.time_axis * 1e9
    lin_h = P @ np.array([1.0, 1.0, 0.0, 0.0])
    circ = P @ np.array([1.0, 0.0, 0.0, 1.0])
    fig, axes = plt.subplots(1, len(q), figsize=(4.2 * len(q), 3.6), constrained_layout=True)
    for k in range(len(q)):
        ax = axes[k]
        ax.plot(t_ns, P[k, :, 0, 0], "k", label="M00")
        ax.plot(t_ns, 0.5 * (lin_h[k, :, 0] + lin_h[k, :, 1]), label="linear co (H->H)")
        ax.plot(t_ns, 0.5 * (lin_h[k, :, 0] - lin_h[k, :, 1]), label="linear cross (H->V)")
        # a mirror flips handedness (V -> -V): "same sense" is the cross channel
        ax.plot(t_ns, 0.5 * (circ[k, :, 0] - circ[k, :, 3]), "--", label="circular opposite sense")
        ax.plot(t_ns, 0.5 * (circ[k, :, 0] + circ[k, :, 3]), "--", label="circular same sense")
        if res.by_bounce is not None:
            inter = res.by_bounce["profile"][k, 1:, :, 0, 0].sum(axis=0)
            ax.plot(t_ns, inter, ":", color="grey", label="M00 after 2-3 reflections")
        ax.set_xlabel("round-trip delay (ns)")
        ax.set_title(f"{np.degrees(angles[k]):.0f} deg: sigma = {res.cross_section[k, 0, 0]:.3g} m^2")
        nz = np.nonzero(P[k, :, 0, 0] > 1e-6 * P[k, :, 0, 0].max())[0]
        if len(nz):
            ax.set_xlim(t_ns[max(nz[0] - 5, 0)], t_ns[min(nz[-1] + 5, len(t_ns) - 1)])
    axes[0].set_ylabel("cross-section per bin (m^2)")
    # one legend beside the panels, covering none of them; each panel keeps its own y scale
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside right upper", fontsize=8)
    fig.suptitle("Range-resolved returns (bin width %.1f mm of range)" % (1e3 * (res.bin_edges[1] - res.bin_edges[0])))
    p2 = out / "cubesat_profiles.png"
    fig.savefig(p2, dpi=80)
    plt.close(fig)

    # range maps: one image per attitude, each with its own colorbar (m)
    fig, axes = plt.subplots(1, len(q), figsize=(4.2 * len(q), 3.8), layout="constrained")
    for k in range(len(q)):
        plot.range_image(res, index=k, ax=axes[k])
        axes[k].set_title(f"{np.degrees(angles[k]):.0f} deg: range")
    fig.suptitle("Range of what each pixel sees (m, positive away from the sensor; blank: nothing seen)")
    p3 = out / "cubesat_range.png"
    fig.savefig(p3, dpi=80)
    plt.close(fig)
    return [p1, p2, p3]


def mueller_figure(name: str, mat: pprender.Material, incidence_deg: float = 30.0) -> Any:
    """The 16 Mueller elements of ``mat`` (M00 and Mij / M00) in the plane of incidence against
    the outgoing angle, at ``incidence_deg`` incidence; returns the figure."""
    import matplotlib.pyplot as plt

    theta_o = np.radians(np.linspace(-89.0, 89.0, 357))
    wi = _sph(np.array(np.radians(incidence_deg)), phi=np.pi)  # transmitter on the -x side
    wo = _sph(np.abs(theta_o))
    wo[theta_o < 0, 0] *= -1
    M = pprender.brdf(mat, np.broadcast_to(wi, wo.shape), wo)
    fig, axes = plt.subplots(4, 4, figsize=(12, 10), sharex=True, layout="constrained")
    for i in range(4):
        for j in range(4):
            ax = axes[i, j]
            if i == j == 0:
                ax.semilogy(np.degrees(theta_o), M[:, 0, 0])
                ax.set_title("M00 (1/sr)")
            else:
                with np.errstate(invalid="ignore", divide="ignore"):
                    ratio = np.where(M[:, 0, 0] > 0, M[:, i, j] / M[:, 0, 0], np.nan)
                ax.plot(np.degrees(theta_o), ratio)
                ax.set_ylim(-1.05, 1.05)
                ax.set_title(f"M{i}{j}/M00")
            if i == 3:
                ax.set_xlabel("theta_o (deg)")
    # a short title (the material's repr is longer than the figure is wide)
    eta = complex(mat.eta)
    what = f"{mat.distribution}, alpha = {mat.alpha:g}, eta = {eta.real:.4g} + {eta.imag:.4g}i"
    what += f", terms {' + '.join(mat.terms)}"
    if "diffuse" in mat.terms:
        what += f" (albedo {mat.diffuse_albedo:g})"
    wl = f" at {mat.wavelength * 1e9:.0f} nm" if mat.wavelength else ""
    fig.suptitle(f"{name}{wl}: {what}\nsp frame, {incidence_deg:g} deg incidence, plane of incidence")
    return fig


def main(outdir: str = "out") -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = cubesat_demo(out)
    theta = np.radians(np.linspace(0.0, 89.0, 179))
    # A rough finish (Beckmann alpha = 0.3) shows the angular structure; the paint keeps
    # its default (GGX 0.5 over a diffuse layer).
    mats = {
        n: materials.get(n, wavelength=1064e-9, **({} if "paint" in n else {"alpha": 0.3}))
        for n in NAMES
    }

    # 1) Monostatic backscatter vs incidence angle: M00 and polarimetric summary.
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    for name, mat in mats.items():
        w = _sph(theta)
        M = pprender.brdf(mat, w, w)
        axes[0].semilogy(np.degrees(theta), M[:, 0, 0], label=name)
        axes[1].plot(np.degrees(theta), polarimetry.depolarization_index(M), label=name)
        axes[2].plot(np.degrees(theta), polarimetry.linear_depolarization_ratio(M), label=name)
    axes[0].set(xlabel="incidence angle (deg)", ylabel="M00 (1/sr)", title="monostatic backscatter BRDF")
    axes[1].set(xlabel="incidence angle (deg)", ylabel="depolarization index", title="depolarization index")
    axes[2].set(xlabel="incidence angle (deg)", ylabel="linear depolarization ratio", title="linear depolarization ratio")
    axes[0].legend(fontsize=8)
    p = out / "backscatter.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    written.append(p)

    # 2) Full normalized Mueller matrix in the plane of incidence, incidence 30 degrees.
    for name, mat in mats.items():
        fig = mueller_figure(name, mat)
        p = out / f"mueller_{name}.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        written.append(p)
    return written


if __name__ == "__main__":
    t0 = time.perf_counter()
    paths = main(sys.argv[1] if len(sys.argv) > 1 else "out")
    print(f"pprender {pprender.__version__}: wrote {len(paths)} figures in {time.perf_counter() - t0:.1f} s")
    for p in paths:
        print(f"  {p.resolve()}")
