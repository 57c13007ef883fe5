"""The main job (``make demo``): Mueller BRDFs of a few named materials across angles.

Writes PNG figures to ``out/`` (or the directory given as the first argument) and prints
their paths. For each material at 1064 nm: the 16 Mueller elements (normalized by M00)
and M00 itself against the scattering geometry, in monostatic backscatter and in the
plane of incidence (specular lobe) at 30 degrees incidence, plus depolarization and
diattenuation of the backscattered return.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import pprender
from pprender import materials, polarimetry

NAMES = ("aluminium", "gold", "fused_silica", "kapton", "white_paint")


def _sph(theta: np.ndarray, phi: float = 0.0) -> np.ndarray:
    return np.stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1
    )


def main(outdir: str = "out") -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
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
    theta_o = np.radians(np.linspace(-89.0, 89.0, 357))
    wi = _sph(np.array(np.radians(30.0)), phi=np.pi)  # transmitter on the -x side
    wo = _sph(np.abs(theta_o))
    wo[theta_o < 0, 0] *= -1
    for name, mat in mats.items():
        M = pprender.brdf(mat, np.broadcast_to(wi, wo.shape), wo)
        fig, axes = plt.subplots(4, 4, figsize=(12, 10), sharex=True, constrained_layout=True)
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
        fig.suptitle(f"{name} at 1064 nm: {mat!r}\nsp frame, incidence 30 deg, plane of incidence")
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
