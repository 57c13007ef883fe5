"""Classifier weights (issue 25): ``"whiten"`` with ``counts`` against the plain cosine.

* The study of ``scripts/classifier_weights.py`` at a small size (3 shapes x 2 paints x 64
  attitudes at resolution 32, 36 held-out attitudes, two Poisson draws each at 300, 3000
  and 30000 counts): the recommended weighting is not worse than the plain cosine beyond
  three paired standard errors, and the old whitening is, at 300 counts (the issue).
* The diagnosed cause on constructed band-limited profiles: the within-class scatter is
  nearly singular, the old whitening loses shape at 300 counts, the new one does not.
* The new weights' limits, checked against closed forms: no direction weighted more than
  ``1 / sqrt(tau)``, the plain cosine with few counts, ``tau`` itself where ``S_r = 0``,
  and ``S_r`` computed by hand.
"""

from __future__ import annotations

import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

import pprender as pp
from pprender import database, materials, so3
from pprender.classify import Classifier, NoiseFreeWeightsWarning

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import classifier_weights as cw  # noqa: E402

CFG = cw.Config(databases=cw.QUICK.databases, n_held=6, n_noise=2, counts=(300.0, 3000.0, 30000.0), n_leak=0)


@pytest.fixture(scope="module")
def study() -> dict:
    db = CFG.databases[0]
    with tempfile.TemporaryDirectory() as tmp:
        mats = {m: materials.get(m) for m in db.materials}
        ds = database.build_database(Path(tmp) / "db.zarr", db.shapes(), mats, so3.grid(db.n_grid),
                                     pp.Lidar(resolution=db.resolution), progress=False)
        held = cw.render_truth(db, ds, lambda i: so3.random(CFG.n_held, seed=CFG.seed + 17 * i), mats)
        names = [cw.NONE, cw.OLD, cw.NEW,
                 '"whiten", counts = 300']
        out = cw.classify(CFG, ds, held, np.random.default_rng(CFG.seed), names=names)
        ds.close()
    return out


def test_recommended_weighting_is_not_worse_than_none(study) -> None:
    """Tolerance: the paired difference (same measurements) may be below zero by at most three
    of its standard errors (over attitudes), a one-sided 0.1 % false alarm per comparison
    when the weightings are equally good."""
    for name in (cw.NEW, '"whiten", counts = 300'):
        for n in CFG.counts:
            for t in ("shape", "material"):
                s = study["rows"][name][(n, t)]
                print(name, n, t, s)
                assert s["diff"] >= -3 * s["diff_se"], (name, n, t, s)


def test_the_old_whitening_loses_at_low_counts(study) -> None:
    # The issue, on held-out attitudes: at 300 counts the old whitening loses shape to the
    # plain cosine (measured -0.4 or so at this size) by more than three standard errors.
    s = study["rows"][cw.OLD][(300.0, "shape")]
    print(s)
    assert s["diff"] < -3 * s["diff_se"] and s["diff"] < -0.1, s


# --------------------------------------------------------------------------- the cause, constructed

B = 64
PULSE_BINS = 1.7  # Gaussian pulse sigma in bins: the 100 ps pulse on 3.75 mm bins


def _profiles(theta: np.ndarray, ratio: float, shape: int) -> np.ndarray:
    """(N, B, 2) co/cross profiles: six reflectors whose ranges and brightness vary smoothly
    with an attitude angle ``theta``, blurred by the pulse; the material sets cross / co."""
    r = np.random.default_rng(5)
    freq, phase, amp0 = r.uniform(1, 4, 6), r.uniform(0, 2 * np.pi, 6), r.uniform(0.3, 1, 6)
    pos = 32 + (12 if shape else 8) * np.sin(np.outer(theta, freq) + phase)
    amp = amp0 * (1 + 0.5 * np.cos(np.outer(theta, freq * (1.3 if shape else 1.0))))
    p = (amp[..., None] * np.exp(-0.5 * ((np.arange(B) - pos[..., None]) / PULSE_BINS) ** 2)).sum(axis=-2)
    return np.stack([p, ratio * p], axis=-1)


def test_near_singular_scatter_old_whitening_fails_new_does_not() -> None:
    classes = [(s, r) for s in (0, 1) for r in (0.2, 0.35)]
    grid = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    cand = np.concatenate([_profiles(grid, r, s) for s, r in classes])
    shape = np.repeat([str(s) for s, _ in classes], len(grid))
    rng = np.random.default_rng(0)
    theta = rng.uniform(0, 2 * np.pi, 100)  # held out: between the grid's angles
    truth = np.repeat([str(s) for s, _ in classes], len(theta))
    mu = np.concatenate([_profiles(theta, r, s) for s, r in classes])
    n, bg = 300.0, 5.0
    lam = mu * (n / mu.sum(axis=(1, 2)))[:, None, None] + bg / (2 * B)
    x = rng.poisson(lam) - bg / (2 * B)
    # the premise: the within-class scatter is nearly singular (the pulse leaves the upper half
    # of the range frequencies empty): most eigenvalues below the old ridge
    u = cand.reshape(len(cand), -1)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    _, cls = np.unique(shape, return_inverse=True)
    r = u - np.array([u[cls == c].mean(axis=0) for c in range(2)])[cls]
    e = np.linalg.eigvalsh(r.T @ r / (len(u) - 2))
    assert np.sum(e < 1e-2 * e.mean()) > len(e) / 2
    acc = {}
    for name, kw in (("none", {}), ("old", {"weights": cw.old_whiten(cand, shape)}),
                     ("new", {"weights": "whiten", "counts": n, "background": bg})):
        clf = Classifier(cand, labels={"shape": shape}, target="shape", **kw)
        acc[name] = float(np.mean(clf.top_k(x, 1).shape[:, 0] == truth))
    print(acc)
    # measured: plain 1.00, old 0.85, new 1.00 (400 measurements: se <= 0.025)
    assert acc["old"] < acc["none"] - 0.08
    assert acc["new"] >= acc["none"] - 0.02


# --------------------------------------------------------------------------- limits of the new weights


def _candidates(rng: np.random.Generator, k: int = 30, b: int = 12) -> tuple[np.ndarray, np.ndarray]:
    return rng.uniform(0.0, 1.0, (k, b, 2)), np.array(["a", "b", "c"] * (k // 3), dtype=object)


def test_no_direction_weighs_more_than_the_noise_allows() -> None:
    # W^T W = (S_r + (tau + lambda) I)^-1 <= I / tau: every eigenvalue at most counts (b = 0)
    cand, lab = _candidates(np.random.default_rng(1))
    for n in (10.0, 1e3, 1e5):
        w = Classifier(cand, labels={"material": lab}, weights="whiten", counts=n).weights
        assert np.linalg.eigvalsh(w.T @ w).max() <= n * (1 + 1e-9)


def test_few_counts_give_the_plain_cosine() -> None:
    # tau = 1e8 dwarfs S_r (unit vectors: eigenvalues <= 2), so W = I / sqrt(tau) to 1e-8
    cand, lab = _candidates(np.random.default_rng(2))
    w = Classifier(cand, labels={"material": lab}, weights="whiten", counts=1e-8).weights
    np.testing.assert_allclose(w * math.sqrt(1e8), np.eye(w.shape[0]), atol=1e-7)
    plain = Classifier(cand).scores(cand[:5])
    whitened = Classifier(cand, labels={"material": lab}, weights="whiten", counts=1e-8).scores(cand[:5])
    np.testing.assert_allclose(whitened, plain, atol=1e-7)


def test_tau_where_every_class_has_one_candidate() -> None:
    # S_r = 0 (no neighbour in any class), so W = ((1 + reg) tau)^(-1/2) I with, by hand,
    # tau = 1 / N + (bg / F) * mean_k (sum_f u_kf)^2 / N^2 for the unit-norm candidates u_k.
    cand = np.random.default_rng(3).uniform(0.0, 1.0, (4, 5, 2))
    lab = np.array(["a", "b", "c", "d"], dtype=object)
    n, bg, reg = 200.0, 30.0, 0.05
    u = cand.reshape(4, 10) / np.linalg.norm(cand.reshape(4, 10), axis=1, keepdims=True)
    tau = 1 / n + (bg / 10) * np.mean(u.sum(axis=1) ** 2) / n**2
    w = Classifier(cand, labels={"material": lab}, weights="whiten", counts=n, background=bg,
                   regularization=reg).weights
    np.testing.assert_allclose(w, np.eye(10) / math.sqrt((1 + reg) * tau), rtol=1e-12)


def test_residual_covariance_by_hand() -> None:
    # One class of three unit vectors at 0, 10 and 30 degrees: nearest neighbours 0 -> 10,
    # 10 -> 0, 30 -> 10, so R = (2 r1 r1^T + r2 r2^T) / 3 with r1 = e(0) - e(10),
    # r2 = e(30) - e(10); Ledoit-Wolf's weight rho = min(b2, d2) / d2 from its definition
    # (d2 = |R - mu I|^2, b2 = sum_i |r_i r_i^T - R|^2 / n^2), S_r = ((1 - rho) R + rho mu I) / 2.
    # With counts = inf (tau = 0): W^-2 = S_r + lambda I, lambda = reg * trace(S_r) / 2.
    ang = np.radians([0.0, 10.0, 30.0])
    cand = np.stack([np.cos(ang), np.sin(ang)], axis=-1)[:, None, :]  # (3, 1, 2)
    e = cand[:, 0]
    res = [e[0] - e[1], e[1] - e[0], e[2] - e[1]]
    big_r = sum(np.outer(v, v) for v in res) / 3
    mu = np.trace(big_r) / 2
    d2 = np.sum((big_r - mu * np.eye(2)) ** 2)
    b2 = sum(np.sum((np.outer(v, v) - big_r) ** 2) for v in res) / 9
    rho = min(b2, d2) / d2
    assert 0 < rho < 1  # the shrinkage is exercised
    s_r = ((1 - rho) * big_r + rho * mu * np.eye(2)) / 2
    reg = 1e-3
    w = Classifier(cand, labels={"material": ["a"] * 3}, weights="whiten", counts=math.inf,
                   regularization=reg).weights
    np.testing.assert_allclose(np.linalg.inv(w.T @ w), s_r + reg * np.trace(s_r) / 2 * np.eye(2), rtol=1e-10,
                               atol=1e-15)


def test_lda_with_counts_keeps_self_matches() -> None:
    cand, lab = _candidates(np.random.default_rng(4))
    clf = Classifier(cand, labels={"material": lab}, weights="lda", counts=1e4, background=3.0)
    top = clf.top_k(cand, 1)
    np.testing.assert_allclose(top.score[:, 0], 1.0, atol=1e-9)


def test_counts_warning_and_errors() -> None:
    cand, lab = _candidates(np.random.default_rng(5))
    with pytest.warns(NoiseFreeWeightsWarning, match="counts="):
        Classifier(cand, labels={"material": lab}, weights="whiten")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Classifier(cand, labels={"material": lab}, weights="lda", counts=math.inf)  # noise-free, said so
        Classifier(cand)  # no learned weights, no warning
    bad = [({"weights": None, "counts": 100.0}, "counts"),
           ({"weights": np.ones(2), "counts": 100.0}, "counts"),
           ({"weights": "whiten", "counts": 0.0}, "counts"),
           ({"weights": "whiten", "counts": -5.0}, "counts"),
           ({"weights": "whiten", "counts": math.nan}, "counts"),
           ({"weights": "whiten", "counts": "300"}, "counts"),
           ({"weights": "whiten", "counts": True}, "counts"),
           ({"weights": "whiten", "counts": 100.0, "background": -1.0}, "background"),
           ({"weights": "whiten", "counts": 100.0, "background": math.inf}, "background"),
           ({"weights": "whiten", "background": 5.0}, "background")]
    for kw, name in bad:
        with pytest.raises(pp.Error, match=f"invalid {name}"):
            Classifier(cand, labels={"material": lab}, **kw)
