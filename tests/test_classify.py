"""pprender.classify: the normalized weighted inner-product classifier.

A small real database (plate + cone x aluminium + white paint x 60 super-Fibonacci
attitudes, resolution 32) is built once per module; the learned-weights test uses a
constructed array example where one channel is dominated by nuisance variation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pprender as pp
from pprender import database, materials, models, so3
from pprender.classify import Classifier, co_cross_projection, mueller_projection, stokes_projection

N_ATT = 60
SENSOR = pp.Lidar(resolution=32)


@pytest.fixture(scope="module")
def setup(tmp_path_factory) -> dict:
    shapes = {"plate": models.plate(0.3, 0.2, 0.01), "cone": models.cone(0.1, 0.3, 32)}
    mats = {"aluminium": materials.get("aluminium"), "white_paint": materials.get("white_paint")}
    path = tmp_path_factory.mktemp("cls") / "db.zarr"
    ds = database.build_database(path, shapes, mats, so3.grid(N_ATT), SENSOR, chunk_attitudes=32, progress=False)
    return {"shapes": shapes, "materials": mats, "ds": ds, "path": path}


def _measure(setup, shape: str, material: str, attitudes: np.ndarray, sensor: pp.Lidar = SENSOR) -> np.ndarray:
    """Noise-free simulated Mueller profiles on the database grid, (N, B, 4, 4)."""
    r = pp.render(pp.Scene(setup["shapes"][shape], setup["materials"][material]), sensor, attitudes,
                  outputs=("profile",))
    return database.pad_profile(r.profile, r.bin_edges, setup["ds"])


def _lit(clf: Classifier) -> np.ndarray:
    """Indices of the candidates whose features are not all zero."""
    return np.flatnonzero(np.any(clf.features != 0, axis=(1, 2)))


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (Rotation.from_quat(a, scalar_first=True) * Rotation.from_quat(b, scalar_first=True)).as_quat(
        scalar_first=True)


def test_projection_conventions(setup) -> None:
    angles = np.linspace(0, np.pi, 7)
    mirror = np.diag([1.0, 1.0, -1.0, -1.0])[None, None]  # a mirror facing the sensor (pprender.lidar)
    depol = np.diag([1.0, 0.0, 0.0, 0.0])[None, None]  # an ideal depolarizer
    for a in angles:
        p = co_cross_projection(a)
        assert np.allclose(p(mirror), [[[1.0, 0.0]]], atol=1e-15)
        assert np.allclose(p(depol), [[[0.5, 0.5]]], atol=1e-15)
    assert mueller_projection()(np.arange(16.0).reshape(1, 1, 4, 4)).tolist() == [[list(np.arange(16.0))]]
    # stokes_projection(s) is what the renderer returns with Lidar(polarization=s)
    s_in = np.array([1.0, 0.0, 0.6, -0.8])
    q = so3.grid(7)
    mu = pp.render(pp.Scene(setup["shapes"]["cone"], setup["materials"]["aluminium"]), SENSOR, q,
                   outputs=("profile",)).profile
    st = pp.render(pp.Scene(setup["shapes"]["cone"], setup["materials"]["aluminium"]),
                   pp.Lidar(resolution=32, polarization=s_in), q, outputs=("profile",)).profile
    # device Stokes vs host Mueller @ s: 1e-6 of the peak (measured 3e-8, float32 on the device)
    assert np.allclose(stokes_projection(s_in)(mu), st, rtol=0, atol=1e-6 * np.abs(st).max())


def test_every_candidate_wins_against_itself_with_score_one(setup) -> None:
    clf = Classifier(setup["ds"])  # full Mueller features
    K = clf.n_candidates
    assert K == 2 * 2 * N_ATT and clf.features.shape[2] == 16
    # candidates that return nothing stay in the database (the aluminium plate seen away
    # from its faces' normals: with orders from the path banks it is dark there) and can
    # match nothing; the others are measured against all
    lit = _lit(clf)
    dark = np.setdiff1d(np.arange(K), lit)
    assert 0 < len(dark) < N_ATT and np.all(dark < N_ATT)  # all plate (0), aluminium (0)
    s = clf.scores(clf.features[lit])
    # score 1 to rounding: unit-normalized float64 inner products, |error| ~ F eps ~ 1e-13
    assert np.allclose(s[np.arange(len(lit)), lit], 1.0, rtol=0, atol=1e-12)
    s[np.arange(len(lit)), lit] = -np.inf
    assert s.max() < 1 - 1e-6  # no exact duplicates in this database (measured max 0.99994)
    top = clf.top_k(clf.features[lit], 3)
    assert np.array_equal(top.index[:, 0], lit)
    assert np.allclose(top.score[:, 0], 1.0, atol=1e-12) and np.all(top.score[:, 1] <= top.score[:, 0])
    ds = setup["ds"]
    k = (1 * 2 + 0) * N_ATT + 17  # cone, aluminium, attitude 17
    r = int(np.flatnonzero(lit == k)[0])
    assert top.shape[r, 0] == "cone" and top.material[r, 0] == "aluminium" and top.attitude_index[r, 0] == 17
    assert np.array_equal(top.attitude[r, 0], ds.quaternion.values[17])
    # a fresh noise-free measurement of a database entry (rendered again, float64) wins too
    m = _measure(setup, "cone", "aluminium", ds.quaternion.values[17:18])
    t = clf.top_k(mueller_projection()(m), 1)
    # float32 storage perturbs the direction by ~6e-8 rad, so 1 - s ~ 1e-15 (measured 6e-16);
    # bound 1e-12
    assert t.index[0, 0] == k and t.score[0, 0] == pytest.approx(1.0, abs=1e-12)


def test_scores_ignore_intensity(setup) -> None:
    clf = Classifier(setup["ds"], projection=co_cross_projection())
    x = clf.features[[5, 130, 200]]
    s = clf.scores(x)
    for c in (1e-9, 3.7, 1e6):
        # scaling by c changes the rounding only: 1e-12
        assert np.allclose(clf.scores(c * x), s, rtol=0, atol=1e-12)


def test_range_offset_search(setup) -> None:
    D = 6
    clf = Classifier(setup["ds"], projection=co_cross_projection(), max_shift=D)
    k = 3 * N_ATT + 40  # cone, white paint, attitude 40
    y = clf.features[k]
    B = y.shape[0]
    lo, hi = np.flatnonzero(np.abs(y).sum(axis=1) > 0)[[0, -1]]
    assert lo > 2 * D and hi < B - 2 * D  # the signal stays on the grid when moved by 2 D bins
    for o in (-D, -2, 0, 3, D):
        x = np.roll(y, o, axis=0)  # the measurement lies o bins farther than the candidate
        s, off = clf.scores(x, return_offsets=True)
        assert s.argmax() == k and s[k] == pytest.approx(1.0, abs=1e-12) and off[k] == o
    # beyond the window the match is no longer exact: the search really is limited to +-D
    s = clf.scores(np.roll(y, D + 2, axis=0))
    assert s[k] < 1 - 1e-3
    # without the search a 2-bin offset already costs (measured 0.91 for this candidate)
    assert Classifier(setup["ds"], projection=co_cross_projection()).scores(np.roll(y, 2, axis=0))[k] < 0.99


def _tilt(q: np.ndarray) -> np.ndarray:
    """Angle between the body z axis (the cone's axis) and the telescope Z (toward the
    sensor), rad."""
    return np.arccos(np.clip(Rotation.from_quat(q, scalar_first=True).apply([0.0, 0.0, 1.0])[..., 2], -1, 1))


def test_held_out_attitude_matches_within_the_grid_spacing(setup) -> None:
    """Attitude estimation for a known shape and material at attitudes between grid points.

    The cone is axisymmetric (spin about its axis changes nothing) and a monostatic
    profile's intensity is unchanged by a roll about the line of sight (the range
    histogram of a rotated image), so what a profile can determine is the tilt between the
    cone's axis and the line of sight. The SO(3) distance modulo both rotations (left
    about Z, right about body z) is exactly the difference of tilts, checked below with
    so3.angular_distance. Since a grid point lies within the covering radius in SO(3), one
    lies within it in tilt; the top match must too.
    """
    ds = setup["ds"].isel(shape=[1])  # the cone
    g = so3.grid(N_ATT)
    cov = so3.covering_radius(g, 50_000, seed=1)  # 1.06 rad for 60 points
    held = so3.random(30, seed=12)
    assert so3.nearest(held, g)[1].min() > 0.1  # really between grid points
    # quotient distance = |tilt difference|: minimize the SO(3) distance over the left
    # (about Z) and right (about body z) rotations, from the best of a 36 x 36 grid with
    # Nelder-Mead (converged to 1e-9 rad)
    from scipy.optimize import minimize

    def rz(t):
        return Rotation.from_rotvec(np.asarray(t)[..., None] * [0.0, 0.0, 1.0]).as_quat(scalar_first=True)

    def dist(ang, a, b):
        return so3.angular_distance(_qmul(_qmul(rz(ang[0]), a), rz(ang[1])), b)

    phi = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    pp_, ps_ = (x.ravel() for x in np.meshgrid(phi, phi))
    for i in range(5):
        a, b = g[i], held[i]
        d0 = so3.angular_distance(_qmul(_qmul(rz(pp_), np.tile(a, (len(pp_), 1))), rz(ps_)), b)
        j = d0.argmin()
        res = minimize(lambda t: dist(t, a, b), [pp_[j], ps_[j]], method="Nelder-Mead",
                       options={"xatol": 1e-10, "fatol": 1e-12})
        assert res.fun == pytest.approx(abs(_tilt(a) - _tilt(b)), abs=1e-6)
    for mat in ("aluminium", "white_paint"):
        clf = Classifier(ds.isel(material=[list(ds.material.values).index(mat)]))
        top = clf.top_k(mueller_projection()(_measure(setup, "cone", mat, held)), 1)
        err = np.abs(_tilt(top.attitude[:, 0]) - _tilt(held))
        print(mat, "tilt error (rad): median", np.median(err), "max", err.max(), "covering radius", cov)
        # measured: median 0.029 / 0.017 rad, max 0.21 / 0.11 rad (aluminium / white paint),
        # against a covering radius of 1.07 rad; random matches would have a median ~0.7 rad
        assert err.max() < cov and np.median(err) < 0.1


def test_profile_is_invariant_under_a_half_turn_about_the_line_of_sight(setup) -> None:
    """Why SO(3) distance alone is the wrong yardstick: a half turn about the line of sight
    leaves the whole Mueller profile unchanged (range unchanged, Stokes frames rotated by
    2 pi), so q and (0, 0, 0, 1) q can never be told apart."""
    q = so3.random(5, seed=13)
    zq = _qmul(np.tile([0.0, 0.0, 0.0, 1.0], (5, 1)), q)
    a = _measure(setup, "plate", "aluminium", q)
    b = _measure(setup, "plate", "aluminium", zq)
    # the image grid maps onto itself under the half turn; rounding of the f32 device sums
    # (measured 1.4e-7 of the peak)
    assert np.allclose(a, b, rtol=0, atol=1e-5 * np.abs(a).max())
    assert np.all(so3.angular_distance(q, zq) == pytest.approx(np.pi))


def _constructed(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Two materials, profiles of 40 bins x 2 channels. Channel 0: the material's
    signature (one peak, or two), scaled by 0.8-1.2, plus 2 % noise. Channel 1: nuisance
    (three random bumps of amplitude 1-3, e.g. glints that depend on attitude), the same
    statistics for both materials."""
    b = np.arange(40)
    sig = {
        "A": np.exp(-0.5 * ((b - 18) / 3.0) ** 2),
        "B": 0.6 * np.exp(-0.5 * ((b - 15) / 2.5) ** 2) + 0.5 * np.exp(-0.5 * ((b - 23) / 2.5) ** 2),
    }
    xs, ys = [], []
    for m in ("A", "B"):
        ch0 = sig[m] * rng.uniform(0.8, 1.2, (n, 1)) + 0.02 * rng.normal(size=(n, 40))
        c, w, amp = rng.uniform(5, 35, (n, 3, 1)), rng.uniform(1.5, 4, (n, 3, 1)), rng.uniform(1, 3, (n, 3, 1))
        ch1 = (amp * np.exp(-0.5 * ((b - c) / w) ** 2)).sum(axis=1)
        xs.append(np.stack([ch0, ch1], axis=-1))
        ys += [m] * n
    return np.concatenate(xs), np.array(ys, dtype=object)


def test_learned_weights_improve_material_classification() -> None:
    rng = np.random.default_rng(14)
    cand, lab = _constructed(rng, 25)
    meas, truth = _constructed(rng, 200)
    acc = {}
    for w in (None, "whiten", "lda", np.array([1.0, 0.0])):
        learned = {"counts": math.inf} if isinstance(w, str) else {}  # no Poisson noise in this example
        clf = Classifier(cand, labels={"material": lab}, weights=w, target="material", **learned)
        acc[str(w)] = float(np.mean(clf.top_k(meas, 1).material[:, 0] == truth))
    print("material accuracy:", acc)
    # measured: plain cosine 0.59 (chance 0.5: channel 1 dominates), whitened 0.98, LDA 1.0,
    # channel 1 weighted out by hand 1.0. Bounds: learned weights >= 0.95 and at least
    # 0.3 above the plain cosine.
    assert acc["None"] < 0.7
    for k in ("whiten", "lda", "[1. 0.]"):
        assert acc[k] >= 0.95 and acc[k] > acc["None"] + 0.3, acc
    # classical LDA (one discriminant direction for two classes) also separates them
    clf = Classifier(cand, labels={"material": lab}, weights="lda", n_components=1, counts=math.inf)
    assert np.mean(clf.top_k(meas, 1).material[:, 0] == truth) >= 0.95


def test_learned_weights_on_the_database(setup) -> None:
    # Every target's weights keep self-matches exact (W x = W y for x = y) and winning
    # (for the candidates that return light: _lit).
    for w, target in (("whiten", "material"), ("lda", "shape"), ("whiten", "attitude")):
        clf = Classifier(setup["ds"], projection=co_cross_projection(), weights=w, target=target, counts=math.inf)
        lit = _lit(clf)
        top = clf.top_k(clf.features[lit], 1)
        assert np.allclose(top.score[:, 0], 1.0, atol=1e-9)
        assert np.mean(top.index[:, 0] == lit) == 1.0


def test_bad_inputs(setup) -> None:
    ds = setup["ds"]
    clf = Classifier(ds, projection=co_cross_projection(), max_shift=2)
    B = clf.features.shape[1]
    with pytest.raises(pp.Error, match=rf"expected \(M, {B}, 2\)"):
        clf.scores(np.ones((3, B - 1, 2)))  # profile of the wrong length
    with pytest.raises(pp.Error, match="expected"):
        clf.scores(np.ones((3, B, 3)))  # wrong channels
    x = clf.features[:2].copy()
    x[1, 5, 0] = np.nan
    with pytest.raises(pp.Error, match="NaN"):
        clf.scores(x)
    with pytest.raises(pp.Error, match="all zero"):
        clf.scores(np.zeros((B, 2)))
    with pytest.raises(pp.Error, match="k"):
        clf.top_k(clf.features[:1], 0)
    with pytest.raises(pp.Error, match="empty"):
        Classifier(ds.isel(attitude=[]))
    with pytest.raises(pp.Error, match="labels"):
        Classifier(ds, labels={"material": ["x"]})
    with pytest.raises(pp.Error, match="K, B, C >= 1"):
        Classifier(np.zeros((0, 10, 2)))
    with pytest.raises(pp.Error, match="max_shift"):
        Classifier(ds, max_shift=-1)
    with pytest.raises(pp.Error, match="target"):
        Classifier(ds, weights="whiten", target="colour")
    with pytest.raises(pp.Error, match="no material labels"):
        Classifier(np.ones((4, 10, 2)), weights="whiten")
    with pytest.raises(pp.Error, match="4800 features"):
        Classifier(np.ones((4, 300, 16)), labels={"material": list("abab")}, weights="whiten")
    with pytest.raises(pp.Error, match="weights"):
        Classifier(ds, projection=co_cross_projection(), weights=np.ones(3))
    # an incomplete database is refused
    half = ds.copy()
    half["complete"] = half["complete"].copy(data=np.zeros(half["complete"].shape, dtype=bool))
    with pytest.raises(pp.Error, match="incomplete"):
        Classifier(half)


def test_a_measurement_object_is_registered_on_the_database_grid(tiny_db_for_measurement):
    """A Measurement of a shape rendered on its own (smaller) range window is placed on the
    database's grid and, noise-free and background-free, scores its own candidate 1."""
    ds, scene, sensor, q, index = tiny_db_for_measurement
    truth = pp.render(scene, sensor, q, outputs=("profile",))
    # the counts of a 1 J pulse spread over 1e6 pulses (photon counting: no PileUpWarning)
    inst = pp.Instrument(pulse_energy=1e-6, target_range=1e5, channels="co_cross_linear",
                         background_rate=1.0, n_pulses=10**6)
    meas = pp.measure(truth, inst, seed=3)
    clf = pp.Classifier(ds, projection=co_cross_projection())
    # exact expectation (signal only): the candidate scores 1 to rounding
    import dataclasses
    exact = dataclasses.replace(meas, counts=meas.signal + meas.background)
    s = clf.scores(exact)
    assert int(np.argmax(s[0])) == index and s[0, index] > 1 - 1e-9
    # Poisson counts: still the best match
    assert int(clf.top_k(meas, k=1).index[0, 0]) == index
    with pytest.raises(pp.Error, match="grid"):
        clf.scores(dataclasses.replace(meas, bin_edges=meas.bin_edges + 0.3 * (meas.bin_edges[1] - meas.bin_edges[0])))


@pytest.fixture(scope="module")
def tiny_db_for_measurement(tmp_path_factory):
    from pprender import so3

    sensor = pp.Lidar(resolution=32)
    shapes = {"cone": models.cone(radius=0.15, height=0.4), "plate": models.plate(width=0.5, height=0.3)}
    mats = {"paint": "white_paint"}
    att = so3.grid(12)
    ds = pp.build_database(tmp_path_factory.mktemp("m") / "db.zarr", shapes, mats, att, sensor,
                                 progress=False)
    scene = pp.Scene(shapes["cone"], "white_paint")
    # candidate index of (cone, paint, attitude 5): shapes x materials x attitudes order
    return ds, scene, sensor, att[5:6], 5
