"""Recovery study of the robust fit (``pprender.fit.maximum_likelihood``): are its
estimates right and its uncertainties calibrated?

Method. Two satellites, truths drawn at random (``numpy.random.default_rng(seed)``):

* ``panels``: a 1U bus of aluminium-like metal (single term, ``alpha`` free) with two
  deployed panels (glass-like cells, white diffuse backs); truths: rotation vectors
  ``(rx, ry, 0.3)`` with ``rx, ry`` uniform in [-0.8, 0.8] rad, ``alpha`` uniform in
  [0.15, 0.5]; free ``(rx, ry, alpha)`` with ``attitude_frame="roll"``;
* ``3U``: a 3U bus with body-mounted panels on its long faces (no antenna); truths
  uniform in the rotation-vector ball of radius 1 rad; free ``(rx, ry)`` with
  ``attitude_frame="roll"``.

The attitude is fitted as the swing ``(rx, ry)`` of ``attitude_frame="roll"`` (the
direction the body is seen from), with the roll about the line of sight fixed: a
monostatic single-bounce profile does not depend on the roll at all
(``pprender.fit``'s module docstring), so it is not scored. Fitting all three rotation
components instead (the first version of this study) leaves a valley of constant
likelihood along the roll, curved in the rotation vector: every such fit had 7-8
optima along it and a curvature of log L up to 7000x its Fisher information, and the
diagnosis flagged all of them.

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
Parameter values that the fit's own diagnosis reports as having no Gaussian sd (the
data do not constrain them, or the optimum lies within one sd of their bound) are not
scored either: their ``z`` is not a test of calibration (a huge sd gives ``z = 0``); they
are counted apart. Calibrated uncertainties give ``|z| < 1`` for 68% and ``|z| < 3`` for
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
        "bounds": {"rx": (-1.2, 1.2), "ry": (-1.2, 1.2), "alpha": (0.05, 0.8)},
        "fitted_parts": ["bus"],
        "materials": lambda th: _panel_materials(th[2]),
        "alpha": lambda th: th[2],
        "model_materials": lambda: _panel_materials(0.3),
        "rotvec": lambda th: np.array([th[0], th[1], 0.3]),
    },
    "3U": {
        "mesh": lambda: models.cubesat("3U", panels="body", antenna=False, detail=1),
        "free": ("rx", "ry"),
        "bounds": {"rx": (-1.2, 1.2), "ry": (-1.2, 1.2)},
        "fitted_parts": None,
        "materials": lambda th: _body_materials(),
        "alpha": lambda th: None,
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
                             lidar=pprender.Lidar(resolution=RESOLUTION, supersampling=2), attitude_frame="roll",
                             bounds=sat["bounds"], fitted_parts=sat["fitted_parts"],
                             alpha_step=0.05)  # (as run for docs/fit-recovery.md; "auto" now renders this bus exactly)
    # the truth in the fitted parameters: the swing of its attitude (the roll is not seen)
    drawn = truth
    alpha = sat["alpha"](drawn)
    truth = fit.attitude_starts(model, att, x0=None if alpha is None else [0.0, 0.0, alpha])[0]
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
        "satellite": name, "index": index, "drawn": drawn.tolist(), "truth": truth.tolist(), "x": r.x.tolist(),
        "z": z, "log_l": r.log_likelihood, "log_l_truth": float(model.log_likelihood(truth, data)),
        "n_modes": len(modes), "trustworthy": r.trustworthy, "problems": r.problems,
        "n_evaluations": r.n_evaluations, "seconds": seconds, "warnings": len(caught),
    }


def _no_gaussian_sd(row: dict) -> set[str]:
    """The parameters the fit's own diagnosis says have no Gaussian sd: those the data
    do not constrain (singular Fisher information) and those within one sd of a bound."""
    import ast

    out: set[str] = set()
    for p in row.get("problems", []):
        for key in ("the data do not constrain ", "within one sd of the bound(s) of "):
            if key in p:
                names = p.split(key, 1)[1].split("]", 1)[0] + "]"
                out |= set(ast.literal_eval(names))
    return out


def score(rows: list[dict]) -> dict:
    z_list, flagged = [], 0
    for row in rows:
        if row["z"] is None:
            continue
        names = SATELLITES[row["satellite"]]["free"] if "satellite" in row else ()
        skip = _no_gaussian_sd(row)
        for name, value in zip(names or [None] * len(row["z"]), row["z"]):
            if name in skip:
                flagged += 1
            else:
                z_list.append(abs(value))
    z = np.array(z_list, dtype=np.float64)
    return {"n": len(rows), "values": len(z), "flagged": flagged,
            "unconstrained": sum(row["z"] is None for row in rows), "within_1": float(np.mean(z < 1)), "within_3": float(np.mean(z < 3)),
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
        "`fit.maximum_likelihood` from no start (its defaults: 128 global points per free parameter, 8 local fits, the diagnosis), the model "
        "rendering with analytic coverage (`ForwardModel`'s default).",
        "",
        "| satellite | truths | parameter values scored | not scored (no Gaussian sd) | within 1 sd | within 3 sd | trustworthy | ambiguous (modes > 1) | median s per fit |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    groups = {name: [r for r in rows if r["satellite"] == name] for name in dict.fromkeys(r["satellite"] for r in rows)}
    for name, g in list(groups.items()) + [("all", rows)]:
        s = score(g)
        lines.append(f"| {name} | {s['n']} | {s['values']} | {s['flagged']} | {s['within_1']:.0%} | {s['within_3']:.0%} | "
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
        f"* Calibration: {s['within_3']:.0%} of the scored values lie within 3 sd and {s['within_1']:.0%} within 1 "
        "(a Gaussian gives 99.7% and 68%). Nearly every fit reports several modes: the bodies are symmetric "
        "about planes through their axes (the 3U's four long faces alike: 8 views of one attitude give one "
        "profile), and `maximum_likelihood` now fits from the mirror views of its best optimum (its step 3), "
        "so the truth's own mode is among those reported.",
        "* \"Trustworthy\" is conservative: the fits the diagnosis flagged are mostly right (see the table), "
        "flagged for a curvature of log L that differs from the Fisher information or a local quadratic model "
        "whose maximum lies a few sd away. On the 3U, whose cells (alpha 0.05) glint, the likelihood at 2e4 counts "
        "has structure finer than the sd (about 0.002 rad); not investigated further.",
        "* What changed since the first version of this study (69% within 3 sd, 38% within 1; every 3U fit "
        "flagged): (1) a renderer bug, analytic coverage missing slivers of one body seen between the pixel "
        "centres beside another's outline (the 3U up to 8.6% too bright over a 20-degree range of rolls; "
        "fixed, with a regression test); (2) the roll about the line of sight, which a monostatic single-bounce "
        "profile does not see, was fitted: with `rx, ry, rz` free it is a valley of constant likelihood, "
        "curved in the rotation vector, and its finite-difference Fisher information came from the renderer's "
        "pixel-scale wiggles (a roll sd of 0.17 rad where log L stays within 0.3 over the whole half turn); the "
        "study now fits the swing of `attitude_frame=\"roll\"`; (3) with `rz` fixed in the telescope frame two "
        "`(rx, ry)` that differ by a roll gave the same profile, and the search found the truth's mirror alone "
        "in two fits, which it called trustworthy (one 182 sd off); the mirror views of step 3 find both.",
        "",
        "## Why the fits used to miss",
        "",
        "With sampled coverage (one visibility sample per sub-pixel) the expected counts step whenever a "
        "silhouette edge crosses a sample point: along a line through the truth the log-likelihood is a "
        "staircase on the `panels` satellite, BOBYQA's trust region collapses on a step, and the Fisher "
        "information by finite differences is wrong. Analytic coverage clips each triangle to the pixel "
        "exactly and the same lines are smooth: docs/fit-smoothness.md measures both and their cost "
        "(`python scripts/fit_smoothness.py --write`; `tests/test_fit_diagnosis.py` checks one truth).",
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
    ap.add_argument("--cache", type=Path, default=Path("/tmp/fit_recovery_roll.jsonl"))
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
