"""Renderer accuracy against analytic scenes, versus image resolution.

``python scripts/render_accuracy.py`` prints a markdown table and writes it to
``docs/render-accuracy.md``. Scenes (monostatic, 1064 nm, 100 ps, default bin width):

* Lambertian sphere (a = 0.5 m, rho = 0.7, icosphere subdivision 7, smooth normals):
  sigma = 8/3 pi a^2 rho, dsigma/dr = 8 pi rho a (r/a)^2 on [-a, 0];
* microfacet sphere (Blinn-Phong m = 20, eta 1.5, single bounce, no shadowing):
  sigma = pi a^2 F(0) (m+2)/(m+1), dsigma/dr = 2 pi^2 a F(0) D(theta), cos theta = -r/a;
* Lambertian plate (0.4 m square, rho = 0.5) tilted 50 deg, spun 0.3 rad about the line
  of sight ("generic") or not ("aligned": two edges parallel to the pixel rows):
  sigma = 4 rho cos^2 t W^2, flat over W sin t;
* Lambertian cone nose-on (radius 0.2, height 0.5, 512 sections, rho = 0.6): a linear
  ramp from the apex to the rim.

The references are convolved with the Gaussian pulse and binned by numerical
integration (tests/test_render.py does the same at the default resolution). Errors:
``total``: relative error of the cross-section; ``profile L1``: sum over bins of
|profile - reference| / sigma; ``profile max``: max over bins / max of the reference.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy.special import ndtr

import pprender
from pprender import models

ROOT = Path(__file__).resolve().parents[1]


def lambertian(rho: float) -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=rho)


def binned(edges: np.ndarray, sigma: float, r: np.ndarray, dsdr: np.ndarray) -> np.ndarray:
    w = np.gradient(r) * dsdr
    cdf = ndtr((edges[:, None] - r[None, :]) / sigma)
    return (np.diff(cdf, axis=0) * w[None, :]).sum(axis=1)


def rot(axis: str, t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], float)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


def scenes():
    a = 0.5
    sph = models.sphere(radius=a, subdivisions=7)
    rho = 0.7
    r = np.linspace(-a, 0, 40001)
    yield ("Lambertian sphere", pprender.Scene(sph, lambertian(rho), smooth=True), np.eye(3),
           8 / 3 * math.pi * a * a * rho, r, 8 * math.pi * rho * a * (r / a) ** 2)
    m, eta = 20.0, 1.5
    f0 = ((eta - 1) / (eta + 1)) ** 2
    mat = pprender.Material("blinn_phong", m=m, eta=eta + 0j, shadowing="none", terms=["single"])
    yield ("microfacet sphere (m 20)", pprender.Scene(sph, mat, smooth=True), np.eye(3),
           math.pi * a * a * f0 * (m + 2) / (m + 1), r,
           2 * math.pi**2 * a * f0 * (m + 2) / (2 * math.pi) * (-r / a) ** m)
    w, rho, t = 0.4, 0.5, math.radians(50)
    plate = pprender.Scene(models.plate(width=w, height=w, thickness=1e-6), lambertian(rho))
    d = w * math.sin(t)
    rp = np.linspace(-d / 2, d / 2, 20001)
    sig = 4 * rho * math.cos(t) ** 2 * w * w
    yield ("plate 50 deg, generic", plate, rot("z", 0.3) @ rot("x", t), sig, rp, np.full_like(rp, sig / d))
    yield ("plate 50 deg, aligned", plate, rot("x", t), sig, rp, np.full_like(rp, sig / d))
    rad, h, rho = 0.2, 0.5, 0.6
    cone = pprender.Scene(models.cone(radius=rad, height=h, sections=512), lambertian(rho))
    sig = 4 * rho * rad / math.hypot(rad, h) * math.pi * rad**2
    rc = np.linspace(-h / 2, h / 2, 20001)
    yield ("cone nose-on", cone, np.eye(3), sig, rc, sig * 2 * (rc + h / 2) / h**2)


def measure(scene, R, sigma_ref, r, dsdr, resolution, supersampling=1, samples=None):
    sensor = pprender.Lidar(polarization=[1, 0, 0, 0], resolution=resolution, supersampling=supersampling,
                            pixel_samples=samples)
    res = pprender.render(scene, sensor, R[None], outputs=("profile",))
    ref = binned(res.bin_edges, sensor.sigma_range, r, dsdr)
    prof = res.profile[0, :, 0]
    n = sensor.effective_resolution(scene.radius)
    return dict(
        n=n * supersampling,
        total=(res.cross_section[0, 0] - sigma_ref) / sigma_ref,
        l1=float(np.abs(prof - ref).sum() / sigma_ref),
        mx=float(np.abs(prof - ref).max() / ref.max()),
    )


def main(write: bool = True) -> str:
    lines = ["# Renderer accuracy against analytic scenes", "",
             "`python scripts/render_accuracy.py` (method in its docstring). `default` is the "
             "resolution `pprender.Lidar()` derives (a pixel = a quarter of the range FWHM); "
             "`ss` = supersampling; `K` = visibility samples per pixel (`pixel_samples`; the "
             "default `\"balanced\"` preset uses 8).", "",
             "| scene | pixels across | K | total rel. error | profile L1 / sigma | profile max / peak |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    for name, scene, R, sig, r, dsdr in scenes():
        default = pprender.Lidar().effective_resolution(scene.radius)
        for label, n, ss, k in [("default/2", default // 2, 1, 1), ("default", None, 1, 1),
                                ("2 x default", 2 * default, 1, 1), ("default, ss 2", None, 2, 1),
                                ("default/2", default // 2, 1, 8), ("default", None, 1, 4),
                                ("default", None, 1, 8), ("default", None, 1, 16),
                                ("2 x default", 2 * default, 1, 8)]:
            m = measure(scene, R, sig, r, dsdr, n, ss, k)
            lines.append(f"| {name} | {m['n']} ({label}) | {k} | {m['total']:+.1e} | {m['l1']:.1e} | {m['mx']:.1e} |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n\nSilhouette edges with a steep range gradient (the cone's rim seen nose-on) and " \
        "edges parallel to the pixel grid are where pixel-centre visibility (K = 1) errs most: both fall " \
        "linearly with the pixel size (resolution or supersampling), except the aligned edge, whose " \
        "error repeats at every multiple of the resolution. K visibility samples per pixel (one in each " \
        "of K rows and K columns) share the pixel's area among the surfaces they see: the edges' " \
        "coverage error falls as 1/K, aligned edges included.\n"
    if write:
        (ROOT / "docs" / "render-accuracy.md").write_text(text)
    return text


if __name__ == "__main__":
    main(write="--no-write" not in sys.argv)
