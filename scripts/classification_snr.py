"""Shape, material and attitude classification against SNR, on held-out synthetic measurements.

``python scripts/classification_snr.py`` prints markdown tables (about 2 minutes on 2 CPU
cores); ``--write`` also writes them to ``docs/classification-snr.md``.
``tests/test_classification_snr.py`` runs a small configuration (:data:`QUICK`) of the
same code.

Experiment (all seeded; SI units), once per material pair (:data:`PAIRS`):

* Database (:func:`pprender.build_database`): 3 shapes x 2 materials x ``n_grid``
  super-Fibonacci attitudes (:func:`pprender.so3.grid`), Mueller profiles at
  ``Lidar(resolution=...)`` (1064 nm, 100 ps FWHM: 15 mm range FWHM, 3.75 mm bins).
  Shapes: a cone (base radius 0.1 m, height 0.3 m, 32 sides), a flat plate
  (0.3 x 0.2 x 0.01 m) and a bare 3U CubeSat bus (0.1 x 0.1 x 0.3405 m box). Materials
  (:mod:`pprender.materials` defaults, one per shape): white and black paint, then
  polished aluminium and white paint.
* Held-out measurements: ``n_held`` Haar-random attitudes per shape x material
  (:func:`pprender.so3.random`), none on the grid, rendered by the exact f64 renderer
  (``quality="reference"``, no BRDF tables) at ``truth_resolution``, finer than the
  database's, and placed on the database's range grid: the database's own approximations
  are part of the error. Attitudes whose return is exactly zero would be unmeasurable at
  any SNR and are dropped (the count is reported).
* Instrument: co/cross linear channels (transmit H; a polarizing beam splitter gives the
  co- and cross-polarized returns; ``pprender.instrument.channel_set("co_cross_linear")``),
  no timing jitter. Each measurement's signal is scaled (equivalently: its pulse energy
  times number of pulses) so that ``SNR = S / sqrt(S + B)`` takes the nominal value, with
  ``S`` the expected signal counts summed over bins and channels and ``B`` a fixed
  background of ``background_counts`` expected counts spread uniformly over the range gate
  and both channels; Poisson counts are drawn with :func:`pprender.measure`
  (``n_noise`` draws per attitude and SNR). The known expected background is subtracted
  before classification.
* Classifier (:class:`pprender.Classifier`): plain cosine score (no learned weights) of
  the co/cross profile against every candidate, range offsets of up to ``max_shift`` bins
  searched; the best candidate gives shape, material and attitude.

Attitude error, modulo what the measurement can see (:func:`aspect_error`). Monostatic,
each pixel's Mueller matrix is ``M00 diag(1, d, -d, -d)`` in the telescope bases (a mirror-like
single reflection from facets met at normal incidence plus depolarized multiple and diffuse
scattering; the double-bounce term, not used here, would add more), and rotating the Stokes
bases leaves that form unchanged. So a roll about the line of sight only rotates the image,
and the range profile, a histogram of the image over range, is unchanged: exactly for
quarter turns (the pixel grid maps onto itself) and to rasterization error otherwise
(1 - cosine of 4e-5 to 6e-3 at resolution 48 for a 30 degree roll of the black-paint
plate and cone, 8 to 300 times less at 192; tests/test_classification_snr.py). What the
profile can determine is the *aspect*: the line of sight in the body frame, ``u = R^T Z``.
We report the angle between the true and estimated ``u``, minimized over the shape's own
symmetries: for the cone (axisymmetric) the difference of the tilts of its axis against
the line of sight; for the boxes (plate, bus) the minimum over their rotation groups (4
and 8 rotations) and over ``u -> -u``, because a centrally symmetric body seen from the
opposite side gives the same profile (a half turn about a transverse axis maps the image of the body to its mirror image, with the
same range histogram and the same ``d``). This equals the SO(3) distance minimized over
rolls about the line of sight and over those symmetries. Attitude errors are given for the
measurements whose shape was identified correctly.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

import pprender
from pprender import database, materials, models, so3
from pprender import instrument as ins
from pprender.classify import Classifier, co_cross_projection

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "classification-snr.md"


@dataclasses.dataclass(frozen=True)
class Config:
    n_grid: int = 1000  # database attitudes per shape x material
    resolution: int = 48  # database image side (pixels); the bodies are ~0.37 m across: 7.7 mm pixels
    truth_resolution: int = 96  # held-out measurements are rendered finer than the database
    n_held: int = 50  # held-out attitudes per shape x material
    n_noise: int = 3  # Poisson draws per held-out attitude and SNR
    snrs: tuple[float, ...] = (1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0, 1000.0)
    background_counts: float = 10.0  # expected background counts per measurement (whole gate, both channels)
    max_shift: int = 2  # range registration: offsets of up to 2 bins (7.5 mm) are searched
    seed: int = 2026
    materials: tuple[str, ...] = ("white_paint", "black_paint")  # pprender.materials names, default finishes


#: Full run (the docs table): about 3 minutes on 2 CPU cores (lavapipe).
FULL = Config()
#: The test's configuration: a smaller database and fewer measurements and SNRs.
QUICK = Config(n_grid=300, resolution=32, truth_resolution=64, n_held=8, n_noise=2, snrs=(1.0, 3.0, 10.0, 1000.0))


# --------------------------------------------------------------------------- shapes and symmetries


def _box_group(extents: tuple[float, float, float]) -> np.ndarray:
    """Proper rotations mapping a box of these extents onto itself: the signed permutation
    matrices with det +1 that only permute axes of equal extent. (k, 3, 3)."""
    e = np.asarray(extents, dtype=float)
    out = []
    for perm in itertools.permutations(range(3)):
        if not np.allclose(e[list(perm)], e, rtol=1e-9, atol=0):
            continue
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[np.arange(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    return np.array(out)


@dataclasses.dataclass(frozen=True)
class ShapeInfo:
    """A shape and what its profile cannot tell apart: ``axisymmetric`` (about body z),
    or the rotation group ``group`` (k, 3, 3) of a box; ``central``: centrally symmetric
    (the opposite side looks the same in co/cross)."""

    mesh: Any
    axisymmetric: bool
    group: np.ndarray | None
    central: bool


def shapes() -> dict[str, ShapeInfo]:
    plate = (0.3, 0.2, 0.01)
    bus = models.BUS_EXTENTS["3U"]
    return {
        "cone": ShapeInfo(models.cone(radius=0.1, height=0.3, sections=32), True, None, False),
        "plate": ShapeInfo(models.plate(*plate), False, _box_group(plate), True),
        "bus_3U": ShapeInfo(models.cubesat("3U", panels=None, antenna=False, detail=0), False, _box_group(bus), True),
    }




def _matrices(q: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(np.asarray(q, dtype=float), scalar_first=True).as_matrix()


def _angle(cos: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(cos, -1.0, 1.0))


def aspect_error(info: ShapeInfo, q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Angle (rad) between the true and estimated line of sight in the body frame
    (``u = R^T Z``), minimized over the shape's symmetries (module docstring). (M,)."""
    u1 = _matrices(q_true)[..., 2, :]  # R^T Z is the third row of R
    u2 = _matrices(q_est)[..., 2, :]
    if info.axisymmetric:
        return np.abs(_angle(u1[..., 2]) - _angle(u2[..., 2]))
    assert info.group is not None
    cands = np.einsum("kij,mj->mki", info.group, u2)  # S u2 for every symmetry S
    dots = np.einsum("mi,mki->mk", u1, cands)
    if info.central:
        dots = np.abs(dots)
    return _angle(dots.max(axis=1))


def face_on_angle(info: ShapeInfo, q: np.ndarray) -> np.ndarray:
    """Angle (rad) between the line of sight and the normal of the flat face closest to
    facing the sensor: the cone's base (its only flat face), a box's faces. (M,)."""
    u = _matrices(q)[..., 2, :]
    if info.axisymmetric:
        return _angle(-u[..., 2])  # the base faces body -z
    return _angle(np.abs(u).max(axis=-1))


# --------------------------------------------------------------------------- experiment


def sensor(cfg: Config) -> pprender.Lidar:
    return pprender.Lidar(resolution=cfg.resolution)


def instrument() -> ins.Instrument:
    """The base instrument (its link budget only sets units: signals are rescaled per
    measurement): 1 mJ, 500 km, 1 m aperture, co/cross linear, background rate 1 count/s
    per channel (rescaled to ``background_counts``), 1e8 pulses (under 0.1 counts per bin and
    pulse at the highest SNR: the photon-counting regime, no PileUpWarning)."""
    return ins.Instrument(pulse_energy=1e-3, target_range=5e5, aperture_diameter=1.0, efficiency=0.3,
                          background_rate=1.0, n_pulses=10**8, channels="co_cross_linear")


def build(cfg: Config, path: Path, *, progress: bool = False) -> Any:
    mats = {m: materials.get(m) for m in cfg.materials}
    return database.build_database(
        path, {k: v.mesh for k, v in shapes().items()}, mats, so3.grid(cfg.n_grid), sensor(cfg),
        attitude_grid={"method": "pprender.so3.grid", "n": cfg.n_grid}, progress=progress,
    )


def grid_edges(ds: Any) -> np.ndarray:
    g = ds.attrs["range_grid"]
    return (np.arange(2 * g["half_bins"] + 1) - g["half_bins"]) * g["bin_width"]


def held_out(cfg: Config, ds: Any) -> dict[str, Any]:
    """Noise-free held-out Mueller profiles on the database grid, with their labels."""
    info = shapes()
    # the truth: the exact f64 renderer (no BRDF tables) at a finer resolution than the database
    sens = pprender.Lidar(resolution=cfg.truth_resolution, quality="reference")
    profs, shape_lab, mat_lab, quats = [], [], [], []
    n_dropped = 0
    for i, (s, m) in enumerate(itertools.product(info, cfg.materials)):
        q = so3.random(cfg.n_held, seed=cfg.seed + 17 * i)
        r = pprender.render(pprender.Scene(info[s].mesh, materials.get(m)), sens, q, outputs=("profile",))
        p = database.pad_profile(r.profile, r.bin_edges, ds)
        keep = p[..., 0, 0].sum(axis=1) > 0
        n_dropped += int((~keep).sum())
        profs.append(p[keep])
        quats.append(q[keep])
        shape_lab += [s] * int(keep.sum())
        mat_lab += [m] * int(keep.sum())
    q = np.concatenate(quats)
    grid_dist = so3.nearest(q, np.asarray(ds.quaternion.values))[1]
    return {"profile": np.concatenate(profs), "shape": np.array(shape_lab, dtype=object),
            "material": np.array(mat_lab, dtype=object), "quaternion": q, "dropped": n_dropped,
            "min_grid_distance": float(grid_dist.min())}


def noisy(cfg: Config, profile: np.ndarray, edges: np.ndarray, snr: float, rng: np.random.Generator
          ) -> ins.Measurement:
    """Poisson measurements of ``profile`` (M, B, 4, 4) with signal scaled to ``snr``
    (module docstring)."""
    base = instrument()
    b_unit = float(base.background_counts(edges).sum())
    inst = dataclasses.replace(base, background_rate=cfg.background_counts / b_unit)
    b = float(inst.background_counts(edges).sum())
    s_target = 0.5 * (snr**2 + math.sqrt(snr**4 + 4.0 * snr**2 * b))  # S / sqrt(S + B) = snr
    s_unit = ins.expected_counts(profile, inst, bin_edges=edges, background=False).sum(axis=(-2, -1))
    gain = s_target / s_unit
    return ins.measure(gain[:, None, None, None] * profile, inst, bin_edges=edges, rng=rng)


def run(cfg: Config, ds: Any, held: dict[str, Any] | None = None) -> dict[str, Any]:
    """Classify ``n_noise`` noisy draws of every held-out profile at every SNR."""
    held = held_out(cfg, ds) if held is None else held
    info = shapes()
    edges = grid_edges(ds)
    clf = Classifier(ds, projection=co_cross_projection(), max_shift=cfg.max_shift)
    rng = np.random.default_rng(cfg.seed)
    rows: list[dict[str, Any]] = []
    for snr in cfg.snrs:
        shape_ok, mat_ok, asp, measured_snr, pred_s, pred_m = [], [], [], [], [], []
        for _ in range(cfg.n_noise):
            meas = noisy(cfg, held["profile"], edges, snr, rng)
            measured_snr.append(meas.snr)
            x = meas.counts - meas.background[None]  # background-subtracted counts (M, B, 2)
            top = clf.top_k(x, 1)
            assert top.shape is not None and top.material is not None and top.attitude is not None
            s_hat, m_hat, q_hat = top.shape[:, 0], top.material[:, 0], top.attitude[:, 0]
            ok = s_hat == held["shape"]
            pred_s.append(s_hat)
            pred_m.append(m_hat)
            shape_ok.append(ok)
            mat_ok.append(m_hat == held["material"])
            a = np.full(len(ok), np.nan)  # NaN where the shape is wrong
            for s in info:
                sel = ok & (held["shape"] == s)
                if sel.any():
                    a[sel] = aspect_error(info[s], held["quaternion"][sel], q_hat[sel])
            asp.append(a)
        shape_ok_a, mat_ok_a = np.concatenate(shape_ok), np.concatenate(mat_ok)
        asp_a = np.concatenate(asp)
        right = np.isfinite(asp_a)

        def stat(f: Any, a: np.ndarray) -> float:
            return float(f(a[right])) if right.any() else math.nan

        rows.append({
            "snr": snr,
            "measured_snr": float(np.mean(np.concatenate(measured_snr))),
            "n": int(len(shape_ok_a)),
            "shape_accuracy": float(shape_ok_a.mean()),
            "material_accuracy": float(mat_ok_a.mean()),
            "joint_accuracy": float((shape_ok_a & mat_ok_a).mean()),
            "aspect_median": stat(np.median, asp_a),
            "aspect_p90": stat(lambda a: np.percentile(a, 90), asp_a),
            # per measurement (n_noise draws of every held-out profile, draw-major)
            "shape_ok": shape_ok_a,
            "material_ok": mat_ok_a,
            "aspect_error": asp_a,
            "predicted_shape": np.concatenate(pred_s),
            "predicted_material": np.concatenate(pred_m),
        })
    grid = np.asarray(ds.quaternion.values)
    # the errors left at the highest SNR, with how close to face-on a flat face was
    last = rows[-1]
    n_held = len(held["profile"])
    residual = []
    for j in np.flatnonzero(~(last["shape_ok"] & last["material_ok"])):
        i = j % n_held
        s = held["shape"][i]
        residual.append({"shape": s, "material": held["material"][i], "predicted_shape": last["predicted_shape"][j],
                         "predicted_material": last["predicted_material"][j],
                         "face_on_deg": float(np.degrees(face_on_angle(info[s], held["quaternion"][i:i + 1])[0]))})
    return {
        "residual": residual,
        "rows": rows,
        "n_measurements": int(len(held["profile"])),
        "dropped": held["dropped"],
        "min_grid_distance": held["min_grid_distance"],
        "covering_radius": so3.covering_radius(grid, 50_000, seed=1),
        "n_bins": int(len(edges) - 1),
        "gate_ns": float(2.0 * (edges[-1] - edges[0]) / pprender.SPEED_OF_LIGHT * 1e9),
    }


def _table(cfg: Config, res: dict[str, Any]) -> list[str]:
    deg = 180.0 / math.pi
    lines = [
        f"{res['n_measurements']} held-out attitudes kept ({res['dropped']} dropped for an exactly zero return), "
        f"each at least {res['min_grid_distance'] * deg:.1f} deg from every grid attitude; "
        f"{cfg.n_noise * res['n_measurements']} measurements per row.",
        "",
        "| SNR | shape accuracy | material accuracy | shape and material | median aspect error (deg) "
        "| 90th pct aspect error (deg) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["rows"]:
        lines.append(
            f"| {r['snr']:g} | {r['shape_accuracy']:.3f} | {r['material_accuracy']:.3f} | {r['joint_accuracy']:.3f} "
            f"| {r['aspect_median'] * deg:.1f} | {r['aspect_p90'] * deg:.1f} |"
        )
    top = res["rows"][-1]
    lines += ["", f"Errors left at SNR {top['snr']:g} ({len(res['residual'])} of {top['n']}), with the angle "
              "between the line of sight and the normal of the flat face nearest to facing the sensor:", ""]
    counts: dict[str, list[float]] = {}
    for r in res["residual"]:
        key = f"{r['shape']} / {r['material']} taken for {r['predicted_shape']} / {r['predicted_material']}"
        counts.setdefault(key, []).append(r["face_on_deg"])
    for key, angles in counts.items():
        at = ", ".join(f"{a:.0f}" for a in sorted(angles))
        lines.append(f"- {key}: {len(angles)} x, flat face at {at} deg from face-on")
    if not counts:
        lines.append("- none")
    return lines + [""]


def markdown(runs: list[tuple[Config, dict[str, Any]]], seconds: float, command: str) -> str:
    deg = 180.0 / math.pi
    cfg, res = runs[0]
    lines = [
        "# Classification accuracy against SNR",
        "",
        f"Generated by `{command}` in {seconds:.0f} s (2 shared CPU cores, lavapipe); the method",
        "is in the script's docstring. Chance level: 1/3 for shape, 1/2 for material.",
        "",
        f"- Database: 3 shapes (cone, radius 0.1 m, height 0.3 m; plate 0.3 x 0.2 x 0.01 m; bare 3U "
        f"CubeSat bus 0.1 x 0.1 x 0.3405 m) x 2 materials (below; `pprender.materials` defaults) x "
        f"{cfg.n_grid} attitudes (`so3.grid`) = {6 * cfg.n_grid} candidates; Mueller profiles at "
        f"`Lidar(resolution={cfg.resolution})` (1064 nm, 100 ps FWHM), {res['n_bins']} range bins of 3.75 mm "
        f"(a {res['gate_ns']:.2f} ns range gate).",
        f"- Held out: {cfg.n_held} Haar-random attitudes per shape x material, rendered by the exact f64 "
        f"renderer (`quality=\"reference\"`) at resolution {cfg.truth_resolution}; {cfg.n_noise} Poisson "
        "draws of each per SNR.",
        "- Instrument: co/cross linear channels (transmit H, polarizing beam splitter), no timing jitter; "
        f"background {cfg.background_counts:g} expected counts per measurement over the gate and both channels "
        "(its expectation is subtracted before matching); the signal of each measurement is scaled so that "
        "SNR = S / sqrt(S + B), S and B summed over bins and channels; Poisson noise by `pprender.measure`.",
        f"- Classifier: `pprender.Classifier`, plain cosine score of the co/cross profile, range offsets of up "
        f"to {cfg.max_shift} bins searched; the best candidate gives shape, material and attitude.",
        "- Attitude error, modulo what the measurement can see: a monostatic profile is unchanged by any roll "
        "about the line of sight (each pixel's Mueller matrix is M00 diag(1, d, -d, -d), which the roll leaves "
        "as it is; the roll only rotates the image), so the profile determines the aspect, the line of sight in "
        "the body frame. Aspect error: the angle between the true and estimated line of sight in the body "
        "frame, minimized over the shape's symmetries (cone: the tilt of its axis; plate and bus: their "
        "rotation groups and the opposite side, which a centrally symmetric body presents identically). "
        "Statistics over the measurements whose shape was right. The grid's covering radius in SO(3) is "
        f"{res['covering_radius'] * deg:.1f} deg (an upper bound on the aspect spacing).",
        "",
    ]
    for c, r in runs:
        lines += [f"## {' vs '.join(c.materials)}", ""] + _table(c, r)
    lines += [
        "## Reading the tables",
        "",
        "A flat face seen nearly face-on returns a single pulse-width echo whose outline the profile cannot",
        "show once the intensity is normalized away, so a cone seen base-on and a plate seen face-on look",
        "alike: those are the shape errors left at high SNR. The paints differ in polarization at every",
        "attitude (white paint's diffuse layer depolarizes, black paint's glossy binder keeps part of the",
        "polarization), so their material is found 97 % of the time from SNR 10. Polished aluminium is",
        "harder: away from its glint it returns little, and that little is multiply scattered and",
        "depolarized like paint, so both its shape and its material stay ambiguous at some attitudes",
        "whatever the SNR. Held-out attitudes were drawn at random, so the accuracies are averages over",
        "attitude; a real target's attitude distribution (e.g. nadir pointing) changes them.",
        "",
    ]
    return "\n".join(lines)


#: Material pairs of the docs table: two paints, then polished aluminium against white paint.
PAIRS = (("white_paint", "black_paint"), ("aluminium", "white_paint"))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write", action="store_true", help=f"write {DOC.relative_to(ROOT)}")
    p.add_argument("--quick", action="store_true", help="the test's small configuration (paints only)")
    args = p.parse_args(argv)
    base = QUICK if args.quick else FULL
    cfgs = [base] if args.quick else [dataclasses.replace(base, materials=m) for m in PAIRS]
    t0 = time.perf_counter()
    runs = []
    for cfg in cfgs:
        with tempfile.TemporaryDirectory() as tmp:
            ds = build(cfg, Path(tmp) / "db.zarr")
            runs.append((cfg, run(cfg, ds)))
    seconds = time.perf_counter() - t0
    command = " ".join(["python scripts/classification_snr.py"] + (["--quick"] if args.quick else [])
                       + (["--write"] if args.write else []))
    text = markdown(runs, seconds, command)
    print(text)
    if args.write:
        DOC.write_text(text)
        print(f"wrote {DOC}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
