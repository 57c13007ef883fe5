"""Recovery study of the robust fit (``pprender.fit.maximum_likelihood``): are its
estimates right and its uncertainties calibrated?

Method. Two satellites, truths drawn at random (``numpy.random.default_rng(seed)``):

* ``panels``: a 1U bus of aluminium-like metal (single term, ``alpha`` free) with two
  deployed panels (glass-like cells, white diffuse backs), free ``(rx, ry, alpha)``,
  ``rz = 0.3`` fixed; truths ``rx, ry`` uniform in [-0.8, 0.8] rad, ``alpha`` in
  [0.15, 0.5];
* ``3U``: a 3U bus with body-mounted panels on its long faces (no antenna), free
  ``(rx, ry, rz)``; truths uniform in the rotation-vector ball of radius 1 rad.

Each truth is rendered at 96 px with 2x2 supersampling and analytic coverage (the data: a
finer pixel grid than the model's 48 px, so not the model's own numbers; sampled coverage
with one sample per sub-pixel is not a stand-in for a real target: on thin panel edges it
is off by more than the Poisson noise, and the diagnosis flagged those fits as not
fitting the data), scaled to ``COUNTS`` expected signal counts with a background, drawn
once (Poisson, seed = truth index) and fitted from no start at all (the global stage
only). Bounds: ``rx, ry`` (and ``rz``) in [-1.2, 1.2] rad, ``alpha`` in [0.05, 0.8].

Scoring, modulo what the data cannot tell apart: a fit reports its best optimum and the
``alternatives`` within 3 in log L (e.g. attitudes related by a half turn about the
line of sight, which co/cross channels cannot see); the mode nearest the truth
(Mahalanobis distance under each mode's own Fisher information) is scored, each
parameter's ``z = (estimate - truth) / sd`` with ``sd`` its Cramer-Rao standard
deviation there (modes where the Fisher information is singular, a parameter the data
do not constrain, are not scored; a truth with only such modes is counted apart).
Calibrated uncertainties give ``|z| < 1`` for 68% and ``|z| < 3`` for
99.7% of the parameter values; the issue's pass band is 55-80% and >= 90%. Fits whose
truth is in no reported mode are misses, counted as ``|z| = inf``.

``python scripts/fit_recovery.py --write`` regenerates ``docs/fit-recovery.md`` (results
cached per truth in ``--cache``, so an interrupted run resumes); ``--quick`` is the small
version the tests run.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import pprender
from pprender import fit, models
from pprender import instrument as ins

COUNTS = 2e4
RESOLUTION = 48
DOC = Path(__file__).resolve().parents[1] / "docs" / "fit-recovery.md"


def _panel_materials(alpha: float) -> dict:
    return {
        "bus": pprender.Material("beckmann", alpha=alpha, eta=1.38 + 10.2j, terms=["single"]),
        "solar_cells": pprender.Material("beckmann", alpha=0.05, eta=1.5 + 0j, terms=["single"]),
        "panel_back": pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.8),
    }


def _body_materials() -> dict:
    return {
        "bus": pprender.Material("beckmann", alpha=0.2, eta=1.38 + 10.2j, terms=["single"]),
        "solar_cells": pprender.Material("beckmann", alpha=0.05, eta=1.5 + 0j, terms=["single"]),
        "panel_back": pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.8),
    }


SATELLITES = {
    "panels": {
        "mesh": lambda: models.cubesat("1U", panels="deployed", antenna=False, detail=1),
        "free": ("rx", "ry", "alpha"),
        "fixed": {"rz": 0.3},
        "bounds": {"rx": (-1.2, 1.2), "ry": (-1.2, 1.2), "alpha": (0.05, 0.8)},
        "fitted_parts": ["bus"],
        "materials": lambda th: _panel_materials(th[2]),
        "model_materials": lambda: _panel_materials(0.3),
        "rotvec": lambda th: np.array([th[0], th[1], 0.3]),
    },
    "3U": {
        "mesh": lambda: models.cubesat("3U", panels="body", antenna=False, detail=1),
        "free": ("rx", "ry", "rz"),
        "fixed": {},
        "bounds": {"rx": (-1.2, 1.2), "ry": (-1.2, 1.2), "rz": (-1.2, 1.2)},
        "fitted_parts": None,
        "materials": lambda th: _body_materials(),
        "model_materials": _body_materials,
        "rotvec": lambda th: np.asarray(th, dtype=np.float64),
    },
}


def draw_truths(name: str, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed + (0 if name == "panels" else 1000))
    if name == "panels":
        return np.column_stack([rng.uniform(-0.8, 0.8, n), rng.uniform(-0.8, 0.8, n), rng.uniform(0.15, 0.5, n)])
    # uniform in the ball of radius 1 rad
    v = rng.standard_normal((n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * rng.uniform(0, 1, (n, 1)) ** (1 / 3)


def one_truth(name: str, truth: np.ndarray, index: int, n_global: int | None = None, n_local: int = 8) -> dict:
    """Render, measure and fit one truth; score it (module docstring)."""
    sat = SATELLITES[name]
    mesh = sat["mesh"]()
    base = pprender.Instrument(pulse_energy=1e-3, target_range=500e3, jitter=20e-12, background_rate=1e5,
                               n_pulses=10**5)
    att = Rotation.from_rotvec(sat["rotvec"](truth)).as_matrix()[None]
    # the data: twice the model's resolution, exact coverage (the model's own renderer at
    # another pixel grid: not the model's numbers, and no rasterization error of its own)
    data_lidar = pprender.Lidar(resolution=2 * RESOLUTION, supersampling=2, coverage="analytic", arithmetic="f64",
                                polarization=base.channels.transmit)
    tr = pprender.render(pprender.Scene(mesh, sat["materials"](truth)), data_lidar, att, outputs=("profile",))
    inst = base.scaled_to(COUNTS, tr)
    data = ins.measure(tr, inst, seed=index)[0]
    model = fit.ForwardModel(mesh, sat["model_materials"](), inst, data.bin_edges, sat["free"],
                             lidar=pprender.Lidar(resolution=RESOLUTION, supersampling=2), fixed=sat["fixed"],
                             bounds=sat["bounds"], fitted_parts=sat["fitted_parts"])
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = fit.maximum_likelihood(model, data, n_global=n_global, n_local=n_local, seed=index)
    seconds = time.perf_counter() - t0
    modes = [(r.x, r.log_likelihood, r.fisher)]
    for x, ll in r.alternatives:
        try:
            modes.append((x, ll, fit.fisher_information(model, x)))
        except pprender.Error:
            modes.append((x, ll, None))
    best = None
    for x, ll, F in modes:
        if F is None or not np.all(np.isfinite(F)) or np.linalg.cond(F) > 1e12:
            continue  # a parameter the data do not constrain there: no Gaussian sd
        d = x - truth
        m2 = float(d @ F @ d)
        if best is None or m2 < best[0]:
            best = (m2, x, F)
    if best is None:
        z = None  # every mode has a singular Fisher information: not scored
    else:
        sd = np.sqrt(np.diag(np.linalg.inv(best[2])))
        z = ((best[1] - truth) / sd).tolist()
    return {
        "satellite": name, "index": index, "truth": truth.tolist(), "x": r.x.tolist(),
        "z": z, "log_l": r.log_likelihood, "log_l_truth": float(model.log_likelihood(truth, data)),
        "n_modes": len(modes), "trustworthy": r.trustworthy, "problems": r.problems,
        "n_evaluations": r.n_evaluations, "seconds": seconds, "warnings": len(caught),
    }


def score(rows: list[dict]) -> dict:
    z = np.abs(np.array([row["z"] for row in rows if row["z"] is not None], dtype=np.float64)).ravel()
    return {"n": len(rows), "values": len(z), "unconstrained": sum(row["z"] is None for row in rows), "within_1": float(np.mean(z < 1)), "within_3": float(np.mean(z < 3)),
            "trustworthy": int(sum(row["trustworthy"] for row in rows)),
            "ambiguous": int(sum(row["n_modes"] > 1 for row in rows)),
            "seconds": float(np.median([row["seconds"] for row in rows]))}


def run(n: int, seed: int, cache: Path | None, n_global: int | None = None, n_local: int = 8,
        satellites: tuple[str, ...] = ("panels", "3U"), log=print) -> list[dict]:
    done: dict[str, dict] = {}
    if cache is not None and cache.exists():
        for line in cache.read_text().splitlines():
            row = json.loads(line)
            done[f"{row['satellite']}/{row['index']}"] = row
    rows = []
    for name in satellites:
        for i, truth in enumerate(draw_truths(name, n, seed)):
            key = f"{name}/{i}"
            if key not in done:
                done[key] = one_truth(name, truth, i, n_global=n_global, n_local=n_local)
                if cache is not None:
                    with cache.open("a") as f:
                        f.write(json.dumps(done[key]) + "\n")
            row = done[key]
            zmax = "-" if row["z"] is None else f"{np.max(np.abs(row['z'])):.2f}"
            log(f"{key}: |z| max {zmax}, modes {row['n_modes']}, "
                f"trustworthy {row['trustworthy']}, {row['seconds']:.1f} s")
            rows.append(row)
    return rows


def write(rows: list[dict], seconds: float, path: Path) -> None:
    lines = [
        "# Fit recovery: are the robust fit's estimates right and its uncertainties calibrated?",
        "",
        f"Generated by `python scripts/fit_recovery.py --write` (method in its docstring); the fits took "
        f"{sum(r['seconds'] for r in rows) / 60:.0f} min in all (2 cores shared with other work) "
        f"on {platform.machine()}, pprender {pprender.__version__}, device {pprender.device_info('auto')['name']}. "
        f"{int(COUNTS)} expected signal counts, {RESOLUTION} px, co/cross linear channels; each truth fitted by "
        "`fit.maximum_likelihood` from no start (its defaults: 128 x 3 global points, 8 local fits, the diagnosis), the model "
        "rendering with analytic coverage (`ForwardModel`'s default).",
        "",
        "| satellite | truths | parameter values | within 1 sd | within 3 sd | trustworthy | ambiguous (modes > 1) | median s per fit |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    groups = {name: [r for r in rows if r["satellite"] == name] for name in dict.fromkeys(r["satellite"] for r in rows)}
    for name, g in list(groups.items()) + [("all", rows)]:
        s = score(g)
        lines.append(f"| {name} | {s['n']} | {s['values']} | {s['within_1']:.0%} | {s['within_3']:.0%} | "
                     f"{s['trustworthy']} | {s['ambiguous']} | {s['seconds']:.1f} |")
    s = score(rows)
    ok = s["within_3"] >= 0.9 and 0.55 <= s["within_1"] <= 0.8
    lines += [
        "",
        f"Target (issue 25): >= 90% within 3 sd and 55-80% within 1 sd: **{'met' if ok else 'not met'}** "
        f"({s['within_3']:.0%} and {s['within_1']:.0%}).",
        "",
        "\"Ambiguous\": the fit reported other optima with log L within 3 of the best (`FitResult.alternatives`); "
        "the mode nearest the truth is scored. \"Trustworthy\": the diagnosis found no problem "
        "(`FitResult.problems`: convergence, curvature against the Fisher information, goodness of fit, bounds).",
        "",
        "## Every truth",
        "",
        "| satellite | # | truth | estimate (best mode) | z of the nearest mode | modes | log L - log L(truth) | problems |",
        "|---|---:|---|---|---|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['satellite']} | {r['index']} | {np.round(r['truth'], 3).tolist()} | {np.round(r['x'], 3).tolist()} | "
            f"{'unconstrained' if r['z'] is None else np.round(r['z'], 2).tolist()} | {r['n_modes']} | {r['log_l'] - r['log_l_truth']:+.1f} | "
            f"{'; '.join(p[:80] for p in r['problems']) or '-'} |")
    lines += [
        "",
        "## What this shows",
        "",
        "* `panels` (the issue's case: free tilt and bus roughness): 91% of the values within 3 sd, 53% within 1 "
        "(the target's 55-80% just missed). Two of the 15 truths are misses that the diagnosis called "
        "trustworthy: in both the fit found one mode, the near-mirror attitude (`ry` reflected about a few "
        "tenths of a radian) with log L 1-3 above the truth's, and never visited the truth's own mode. "
        "13 of the 15 fits reported more than one mode, typically the truth's and this mirror: the data cannot tell them apart, and the "
        "search does not yet look for the mirror of what it found (not done: starting local fits from the best "
        "optimum with each free rotation component's sign flipped would visit it).",
        "* `3U` (the whole rotation free, a 3U bus with a panel on each long face): not calibrated, 47% within 3 "
        "sd, and the diagnosis says so for every one of the 15 fits (no trustworthy result): 7 or 8 distinct "
        "optima per fit, and at the best one the curvature of log L differs from the Fisher information by up to "
        "7000x and the local quadratic model's maximum lies 1-18 sd away. This bus has a fourfold symmetry about "
        "its long axis and glints from its glass-like cells (alpha 0.05), so its likelihood at 2e4 counts is a "
        "field of narrow peaks that neither the global stage's 384 points nor the Gaussian sd describe; a "
        "posterior over the modes (emcee from each, or a finer global stage) is what such a target needs.",
        "",
        "## Why the fits used to miss",
        "",
        "With sampled coverage (one visibility sample per sub-pixel) the expected counts step whenever a "
        "silhouette edge crosses a sample point: along a line through the truth the log-likelihood is a "
        "staircase (RMS residual to a smooth quartic 0.5 to 21 in log L over +-3 sd on the `panels` satellite, "
        "`tests/test_fit_diagnosis.py` measures it), BOBYQA's trust region collapses on a step, and the Fisher "
        "information by finite differences is wrong by up to 15x in sd. Analytic coverage clips each "
        "triangle to the pixel exactly: the same line is smooth (residual below 0.02), and with the f64 CPU "
        "renderer it costs what the sampled render costs on lavapipe (12 ms per attitude here).",
        "",
    ]
    # keep the section benchmarks/bench_fit.py writes
    mark = "## Cost of a roughness fit"
    old = path.read_text() if path.exists() else ""
    tail = ("\n" + mark + old.split(mark, 1)[1]) if mark in old else ""
    path.write_text("\n".join(lines) + tail)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=15, help="truths per satellite (default 15: 30 truths, 90 parameter values)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/fit_recovery.jsonl"))
    ap.add_argument("--write", action="store_true", help=f"write {DOC.name}")
    ap.add_argument("--quick", action="store_true", help="3 truths of the panels satellite, no cache")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.quick:
        rows = run(3, a.seed, None, satellites=("panels",))
    else:
        rows = run(a.n, a.seed, a.cache)
    s = score(rows)
    print(json.dumps(s))
    if a.write:
        write(rows, time.perf_counter() - t0, DOC)
    return 0


if __name__ == "__main__":
    sys.exit(main())
