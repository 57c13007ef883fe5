"""pprender.so3 (rotation grids and distances) and pprender.database (candidate databases).

SO(3) checks are against scipy's Rotation and Haar-measure identities; database checks
against direct pprender.render calls. One small real database (sphere + 1U CubeSat x 2
materials x 30 attitudes at resolution 32) is built once per module.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import tracemalloc
import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pprender as pp
from pprender import database, materials, models, so3

# --------------------------------------------------------------------------- so3


def _matrices(q: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(q, scalar_first=True).as_matrix()


def _moment_errors(q: np.ndarray) -> dict[str, float]:
    """Errors of Haar moments over the rotations q: E[tr R] = 0, E[tr^2 R] = 1,
    E[R_ij] = 0, E[R_ij R_kl] = delta_ik delta_jl / 3 (Schur orthogonality for SO(3))."""
    R = _matrices(q)
    n = len(R)
    tr = np.trace(R, axis1=1, axis2=2)
    second = np.einsum("nij,nkl->ijkl", R, R) / n - np.einsum("ik,jl->ijkl", np.eye(3), np.eye(3)) / 3.0
    return {
        "tr": abs(tr.mean()),
        "tr2": abs((tr**2).mean() - 1.0),
        "R": float(np.abs(R.mean(axis=0)).max()),
        "RR": float(np.abs(second).max()),
    }


def test_grid_haar_moments_beat_random_sampling() -> None:
    n = 1000
    g = so3.grid(n)
    assert g.shape == (n, 4)
    assert np.allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-15) and np.all(g[:, 0] >= 0)
    # Tolerance: 0.2 x the standard error of a Haar-random sample of the same size, i.e.
    # the grid must integrate these moments at least 5x better than Monte Carlo. Standard
    # deviations under Haar: tr R: 1; tr^2 R: sqrt(E tr^4 - 1) = sqrt(2); R_ij: 1/sqrt(3);
    # R_ij R_kl: at most 1 (|R_ij R_kl| <= 1).
    sd = {"tr": 1.0, "tr2": np.sqrt(2.0), "R": 1.0 / np.sqrt(3.0), "RR": 1.0}
    tol = {k: 0.2 * v / np.sqrt(n) for k, v in sd.items()}
    err = _moment_errors(g)
    # measured: tr 1.0e-3, tr2 2.9e-3, R 7.3e-4, RR 7.3e-4 (tolerances 6.3e-3, 8.9e-3, 3.7e-3, 6.3e-3)
    for k in err:
        assert err[k] < tol[k], (k, err[k], tol[k])
    # The same tolerances reject independent Haar samples (scipy): the test can fail.
    rand = Rotation.random(n, rng=np.random.default_rng(2)).as_quat(scalar_first=True)
    err_r = _moment_errors(rand)
    assert any(err_r[k] > tol[k] for k in err_r), err_r


def test_ball_radius_is_the_haar_measure_of_a_ball() -> None:
    # Fraction of 200000 scipy Haar samples within ball_radius(n) of the identity: 1/n
    # within 4 binomial standard deviations.
    m = 200_000
    mags = Rotation.random(m, rng=np.random.default_rng(3)).magnitude()
    for n in (3, 10, 100):
        p = 1.0 / n
        frac = np.mean(mags < so3.ball_radius(n))
        assert abs(frac - p) < 4 * np.sqrt(p * (1 - p) / m), (n, frac)
    # large n: theta - sin theta = theta^3/6 (1 - theta^2/20 + ...) gives
    # theta = t0 (1 + t0^2/60 + O(t0^4)) with t0 = (6 pi / n)^(1/3); the O(t0^4) term is
    # below 1e-8 relative at n = 1e6 (t0 = 0.027), the second term 1.2e-5.
    t0 = (6 * np.pi / 1e6) ** (1 / 3)
    assert so3.ball_radius(10**6) == pytest.approx(t0 * (1 + t0**2 / 60), rel=1e-8)


def test_grid_covering_radius_and_separation_vs_random() -> None:
    n = 1000
    g = so3.grid(n)
    rand = Rotation.random(n, rng=np.random.default_rng(4)).as_quat(scalar_first=True)
    b = so3.ball_radius(n)  # 0.266 rad
    # Covering radius estimated with 50000 probes (> 50 per grid point). Measured:
    # grid 0.397 rad (1.49 b), random 0.58 rad (2.2 b). Bounds: the grid within 1.7 b, and
    # at least 20 % below random sampling's.
    cov_g = so3.covering_radius(g, 50_000, seed=5)
    cov_r = so3.covering_radius(rand, 50_000, seed=5)
    assert cov_g < 1.7 * b and cov_g < 0.8 * cov_r, (cov_g, cov_r, b)
    # Nearest-neighbour distances: the grid is well separated and regular (measured min
    # 1.16 b, coefficient of variation 0.05); random points are not (min 0.12 b, CV 0.33).
    nn_g = so3.nearest_neighbour_distances(g)
    nn_r = so3.nearest_neighbour_distances(rand)
    assert nn_g.min() > 0.9 * b and nn_g.std() / nn_g.mean() < 0.15
    assert nn_r.min() < 0.5 * b and nn_r.std() / nn_r.mean() > 0.25


def test_angular_distance_matches_scipy() -> None:
    rng = np.random.default_rng(6)
    r1 = Rotation.random(500, rng=rng)
    r2 = Rotation.random(500, rng=rng)
    # near-identical (1e-9 .. 1e-3 rad apart) and near-antipodal (pi - 1e-6) pairs
    axes = rng.normal(size=(500, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    small = np.exp(rng.uniform(np.log(1e-9), np.log(1e-3), size=500))
    r3 = r1 * Rotation.from_rotvec(axes * small[:, None])
    r4 = r1 * Rotation.from_rotvec(axes * (np.pi - 1e-6))
    for a, b in ((r1, r2), (r1, r3), (r1, r4)):
        q1 = a.as_quat(scalar_first=True)
        q2 = b.as_quat(scalar_first=True)
        ref = (a.inv() * b).magnitude()
        # both in float64: 1e-12 rad absolute (relative 1e-6 for the 1e-9 rad pairs)
        assert np.allclose(so3.angular_distance(q1, q2), ref, rtol=1e-6, atol=1e-12)
        assert np.allclose(so3.angular_distance(q1, -q2), ref, rtol=1e-6, atol=1e-12)  # q ~ -q
    # broadcasting: (5, 1, 4) against (1, 7, 4)
    q = so3.random(12, seed=7)
    d = so3.angular_distance(q[:5, None], q[None, 5:])
    ref = (Rotation.from_quat(q[:5, None].repeat(7, 1).reshape(-1, 4), scalar_first=True).inv()
           * Rotation.from_quat(q[None, 5:].repeat(5, 0).reshape(-1, 4), scalar_first=True)).magnitude()
    assert d.shape == (5, 7) and np.allclose(d.ravel(), ref, atol=1e-12)


def test_nearest_matches_brute_force_scipy() -> None:
    g = so3.grid(300)
    queries = Rotation.random(200, rng=np.random.default_rng(8))
    idx, dist = so3.nearest(queries.as_quat(scalar_first=True), g, block=64)
    rg = Rotation.from_quat(g, scalar_first=True)
    all_d = np.stack([(queries[i].inv() * rg).magnitude() for i in range(len(queries))])
    assert np.array_equal(idx, np.argmin(all_d, axis=1))
    assert np.allclose(dist, all_d.min(axis=1), atol=1e-12)


def test_so3_bad_inputs() -> None:
    with pytest.raises(pp.Error, match="n"):
        so3.grid(0)
    with pytest.raises(pp.Error, match=r"\(\.\.\., 4\)"):
        so3.angular_distance(np.zeros(3), np.zeros(3))
    with pytest.raises(pp.Error, match="unit norm"):
        so3.angular_distance([1.0, 0, 0, 0], [2.0, 0, 0, 0])
    with pytest.raises(pp.Error, match="non-finite"):
        so3.angular_distance([np.nan, 0, 0, 0], [1.0, 0, 0, 0])
    with pytest.raises(pp.Error, match="broadcast"):
        so3.angular_distance(so3.grid(3), so3.grid(4))


# --------------------------------------------------------------------------- database

N_ATT = 30
CHUNK = 8  # 4 attitude chunks per (shape, material): 16 chunks in all


@pytest.fixture(scope="module")
def setup() -> dict:
    return {
        "shapes": {"sphere": models.sphere(0.1, 2), "1U": models.cubesat("1U", detail=1)},
        "materials": {"aluminium": materials.get("aluminium"), "white_paint": materials.get("white_paint")},
        "attitudes": so3.grid(N_ATT),
        "sensor": pp.Lidar(resolution=32),
    }


def _build(path, setup, **kw):
    kw.setdefault("chunk_attitudes", CHUNK)
    kw.setdefault("progress", False)
    kw.setdefault("attitude_grid", {"method": "so3.grid", "n": N_ATT})
    return database.build_database(
        path, setup["shapes"], setup["materials"], setup["attitudes"], setup["sensor"], **kw
    )


@pytest.fixture(scope="module")
def db(tmp_path_factory, setup):
    path = tmp_path_factory.mktemp("db") / "ref.zarr"
    ds = _build(path, setup)
    return path, ds


def _bits(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.uint32 if a.dtype == np.float32 else np.uint64)


def test_layout_coordinates_and_attributes(db, setup) -> None:
    path, ds = db
    assert ds.profile.dims == ("shape", "material", "attitude", "range", "mueller_row", "mueller_col")
    assert list(ds.shape.values) == ["sphere", "1U"] and list(ds.material.values) == ["aluminium", "white_paint"]
    assert ds.profile.dtype == np.float32 and ds.profile.attrs["units"] == "m2"
    assert np.array_equal(ds.quaternion.values, setup["attitudes"])
    assert list(ds.quaternion_component.values) == list("wxyz")
    w = setup["sensor"].effective_bin_width()
    K = ds.attrs["range_grid"]["half_bins"]
    assert ds.range.attrs["units"] == "m" and ds.time.attrs["units"] == "s"
    assert np.allclose(ds.range.values, (np.arange(2 * K) - K + 0.5) * w, rtol=0, atol=1e-15)
    assert np.allclose(ds.time.values, 2 * ds.range.values / pp.SPEED_OF_LIGHT, rtol=1e-15, atol=0)
    assert ds.complete.values.all() and np.isfinite(ds.profile.values).all()
    a = ds.attrs
    assert a["pprender_version"] == pp.__version__ and a["model_version"] == pp.MODEL_VERSION
    assert a["sensor"] == json.loads(json.dumps(dataclasses.asdict(setup["sensor"])))
    assert a["attitudes"]["count"] == N_ATT and a["attitudes"]["grid"] == {"method": "so3.grid", "n": N_ATT}
    assert a["chunk_attitudes"] == CHUNK and a["dtype"] == "float32"
    assert [s["n_faces"] for s in a["shapes"]] == [len(m.faces) for m in setup["shapes"].values()]
    assert ds.n_faces.values.tolist() == [len(m.faces) for m in setup["shapes"].values()]
    assert datetime.datetime.fromisoformat(a["created"]).tzinfo is not None
    # every material parameter is recorded: rebuilding from the attributes gives the same BRDF
    rng = np.random.default_rng(9)
    wi, wo = np.abs(rng.normal(size=(2, 20, 3)))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    for spec, (name, m) in zip(a["materials"], setup["materials"].items()):
        assert spec["name"] == name and spec["kind"] == "uniform"
        m2 = pp.Material(**{**spec["material"], "eta": complex(*spec["material"]["eta"])})
        assert np.array_equal(pp.brdf(m2, wi, wo), pp.brdf(m, wi, wo))


def test_material_parameters_round_trip() -> None:
    # A material with non-default settings everywhere (Blinn-Phong m, eta = inf, Smith,
    # diffuse, 532 nm, ...); the named materials are checked in the layout test.
    rng = np.random.default_rng(10)
    wi, wo = np.abs(rng.normal(size=(2, 30, 3)))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    for m in (
        pp.Material("blinn_phong", m=30.0, eta=complex(np.inf, 0), shadowing="smith", smith_g1="walter",
                    terms=("single", "diffuse"), diffuse_albedo=0.3, wavelength=532e-9, name="bp",
                    correlation_length=2e-5, coherent_backscatter=False),
    ):
        p = database._material_params(m)
        json.dumps(p, allow_nan=False)  # strict JSON (eta = inf is stored as a string)
        m2 = database._material_from_params(json.loads(json.dumps(p)))
        assert database._material_params(m2) == p
        assert np.array_equal(pp.brdf(m, wi, wo), pp.brdf(m2, wi, wo))


def test_profiles_equal_direct_renders_on_a_common_grid(db, setup) -> None:
    _, ds = db
    K = ds.attrs["range_grid"]["half_bins"]
    for i, (sname, mesh) in enumerate(setup["shapes"].items()):
        for j, m in enumerate(setup["materials"].values()):
            r = pp.render(pp.Scene(mesh, m), setup["sensor"], setup["attitudes"], outputs=("profile",))
            k_s = r.profile.shape[1] // 2
            stored = ds.profile.isel(shape=i, material=j).values
            # bit-exact placement: the render's bins at their own ranges, zeros elsewhere
            assert np.array_equal(stored[:, K - k_s : K + k_s], r.profile.astype(np.float32))
            assert not stored[:, : K - k_s].any() and not stored[:, K + k_s :].any()
            assert np.allclose(ds.range.values[K - k_s : K + k_s], r.range_axis, rtol=0, atol=1e-12)
            # sums over range are the total cross-sections (float32 storage: 1e-6 relative)
            tot = stored.astype(np.float64).sum(axis=1)
            assert np.allclose(tot, r.cross_section, rtol=0, atol=1e-6 * np.abs(r.cross_section).max())
    # the sphere (radius 0.1 m) needs fewer bins than the 1U CubeSat with panels and antenna
    half = ds.attrs["range_grid"]["shape_half_bins"]
    assert half["sphere"] < half["1U"] == K


class _Counting:
    """pprender.render with a call counter; raises after ``fail_after`` calls if given."""

    def __init__(self, fail_after: int | None = None) -> None:
        self.calls = 0
        self.fail_after = fail_after

    def __call__(self, scene, sensor, attitudes):
        if self.fail_after is not None and self.calls >= self.fail_after:
            raise RuntimeError("simulated crash")
        self.calls += 1
        return pp.render(scene, sensor, attitudes, outputs=("profile",))


def test_interrupted_build_resumes_bit_for_bit(db, setup, tmp_path) -> None:
    ref_path, ref = db
    path = tmp_path / "resumed.zarr"
    n_shapes = len(setup["shapes"])
    k = 5  # chunks written before the crash
    crash = _Counting(fail_after=n_shapes + k)  # probe renders (one per shape), then k chunks
    with pytest.raises(RuntimeError, match="simulated crash"):
        _build(path, setup, render=crash)
    chunks = database.list_chunks(path)
    assert len(chunks) == 16 and sum(c.done for c in chunks) == k
    assert [c.done for c in chunks] == [True] * k + [False] * (16 - k)  # written in order, one by one
    # A crash between a chunk's data and its flag leaves data without the flag: simulate
    # it with garbage in the next chunk's data; the resumed build must rewrite it.
    import zarr

    c = chunks[k]
    zarr.open_group(str(path), mode="r+")["profile"][c.shape, c.material, c.start : c.stop] = 7.0
    resume = _Counting()
    ds = _build(path, setup, render=resume)
    assert resume.calls == 16 - k  # complete chunks skipped, no probe (same parameters)
    assert np.array_equal(_bits(ds.profile.values), _bits(ref.profile.values))
    assert np.array_equal(ds.complete.values, ref.complete.values)
    strip = lambda a: {k_: v for k_, v in a.items() if k_ != "created"}  # noqa: E731
    assert strip(ds.attrs) == strip(ref.attrs)
    # a third run does nothing
    again = _Counting()
    _build(path, setup, render=again)
    assert again.calls == 0


def test_write_chunk_in_any_order_is_idempotent(db, setup, tmp_path) -> None:
    _, ref = db
    path = tmp_path / "chunks.zarr"
    created = database.create_database(
        path, setup["shapes"], setup["materials"], setup["attitudes"], setup["sensor"],
        chunk_attitudes=CHUNK, attitude_grid={"method": "so3.grid", "n": N_ATT},
    )
    assert created
    chunks = database.list_chunks(path)
    assert not any(c.done for c in chunks)
    assert [(c.start, c.stop) for c in chunks[:4]] == [(0, 8), (8, 16), (16, 24), (24, 30)]
    ds = database.open_database(path)
    assert np.isnan(ds.profile.values).all()  # pending chunks read as NaN
    order = np.random.default_rng(11).permutation(len(chunks))
    for i in order:  # a flat index, as a Dask task would pass it
        assert database.write_chunk(path, int(i)) is True
    counting = _Counting()
    assert database.write_chunk(path, chunks[3], render=counting) is False and counting.calls == 0
    ds = database.open_database(path)
    assert np.array_equal(_bits(ds.profile.values), _bits(ref.profile.values))
    assert all(c.done for c in database.list_chunks(path))
    with pytest.raises(pp.Error, match="chunk"):
        database.write_chunk(path, 16)


def test_changed_parameters_raise_unless_overwrite(db, setup, tmp_path, monkeypatch) -> None:
    path = tmp_path / "p.zarr"
    small = {**setup, "attitudes": setup["attitudes"][:4]}
    _build(path, small, chunk_attitudes=2)
    with pytest.raises(pp.Error, match=r"different parameters \(sensor\)"):
        _build(path, {**small, "sensor": pp.Lidar(resolution=33)}, chunk_attitudes=2)
    with pytest.raises(pp.Error, match=r"different parameters \(attitudes\)"):
        _build(path, {**small, "attitudes": setup["attitudes"][1:5]}, chunk_attitudes=2)
    with pytest.raises(pp.Error, match=r"different parameters \(materials\)"):
        _build(path, {**small, "materials": {"aluminium": materials.get("aluminium", alpha=0.2),
                                              "white_paint": setup["materials"]["white_paint"]}},
               chunk_attitudes=2)
    # a store built by another model (pprender.MODEL_VERSION) is not resumed into
    monkeypatch.setattr(pp, "MODEL_VERSION", pp.MODEL_VERSION + 1)
    with pytest.raises(pp.Error, match=r"different parameters \(model_version\)"):
        _build(path, small, chunk_attitudes=2)
    monkeypatch.undo()
    ds = _build(path, {**small, "sensor": pp.Lidar(resolution=33)}, chunk_attitudes=2, overwrite=True)
    assert ds.attrs["sensor"]["resolution"] == 33 and ds.complete.values.all()
    # something that is not a database is never removed, even with overwrite
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("x")
    with pytest.raises(pp.Error, match="not a pprender database"):
        _build(other, small)
    with pytest.raises(pp.Error, match="only pprender databases"):
        _build(other, small, overwrite=True)
    assert (other / "keep.txt").exists()
    # an empty directory is used as is
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _build(empty, small, chunk_attitudes=2).complete.values.all()


def test_memory_does_not_grow_with_attitudes(setup, tmp_path) -> None:
    # A stand-in render (numpy, so tracemalloc sees its arrays) with 256 bins: a chunk of
    # 16 attitudes is 16 x 256 x 16 x 8 B = 0.5 MB; the whole 512-attitude database would
    # be 8.4 MB as float32. The builder's peak must not grow with the attitude count.
    w = setup["sensor"].effective_bin_width()
    K = 128
    calls = []

    def fake(scene, sensor, q):
        # -1: the probe render, before the store exists
        calls.append(sum(c.done for c in database.list_chunks(path)) if path.exists() else -1)
        r = (np.arange(2 * K) - K + 0.5) * w
        prof = np.exp(-(((r[None] - 0.05 * q[:, :1]) / 0.01) ** 2))[..., None, None] * np.arange(1, 17).reshape(4, 4)
        return types.SimpleNamespace(profile=prof, bin_edges=(np.arange(2 * K + 1) - K) * w)

    shapes = {"sphere": setup["shapes"]["sphere"]}
    mats = {"aluminium": setup["materials"]["aluminium"]}
    peaks = {}
    for n in (64, 64, 512):  # the first run warms up imports and caches
        path = tmp_path / f"mem{n}_{len(peaks)}.zarr"
        calls.clear()
        tracemalloc.start()
        database.build_database(path, shapes, mats, so3.grid(n), setup["sensor"], chunk_attitudes=16,
                                render=fake, progress=False)
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        # the store is written chunk by chunk: before chunk render i, i chunks are complete
        assert calls == [-1] + list(range(n // 16))
    print("peak traced memory (bytes):", peaks)
    # measured: 1.4 MB (64) and 1.5 MB (512); growth allowed: 1 MB (< 2 chunks)
    assert peaks[512] < peaks[64] + 1e6 and peaks[512] < 4e6, peaks


def test_stokes_database_and_part_materials(setup, tmp_path) -> None:
    s_in = (1.0, 0.6, 0.0, 0.8)
    sensor = pp.Lidar(resolution=32, polarization=s_in)
    plate = models.plate(0.2, 0.1, 0.01)
    al, wp = setup["materials"]["aluminium"], setup["materials"]["white_paint"]
    parts = {"front": al, "back": wp, "edge": wp}
    # the plate face-on and five grid attitudes: at those five the aluminium (orders from
    # the path banks) returns 9e-9 m^2 at most, and 1e-6 of that would be finer than the
    # profile's fixed-point quantum (2^-40 of a pixel's largest value, docs/rendering.md)
    q = np.vstack([[1.0, 0.0, 0.0, 0.0], setup["attitudes"][:5]])
    ds = database.build_database(tmp_path / "s.zarr", {"plate": plate}, {"al_front": parts, "al": al}, q, sensor,
                                 chunk_attitudes=4, progress=False)
    assert ds.profile.dims[-1] == "stokes" and list(ds.stokes.values) == list("IQUV")
    assert ds.attrs["materials"][0]["kind"] == "parts"
    for j, m in enumerate((parts, al)):
        ref = pp.render(pp.Scene(plate, m), pp.Lidar(resolution=32), q, outputs=("profile",)).profile @ np.array(s_in)
        got = ds.profile.isel(shape=0, material=j).values.astype(np.float64)
        # Stokes on the device vs Mueller @ s on the host, float32 storage: 1e-6 of the peak
        # (measured 3e-8)
        assert np.allclose(got, ref, rtol=0, atol=1e-6 * np.abs(ref).max())


def test_progress_bar(setup, tmp_path, capsys) -> None:
    _build(tmp_path / "bar.zarr", {**setup, "attitudes": setup["attitudes"][:4]}, chunk_attitudes=2, progress=True)
    err = capsys.readouterr().err
    assert "8/8" in err and "chunk" in err


def test_database_bad_inputs(setup, tmp_path) -> None:
    base = dict(shapes=setup["shapes"], materials=setup["materials"], attitudes=setup["attitudes"][:2],
                sensor=setup["sensor"], progress=False)
    p = tmp_path / "bad.zarr"

    def build(**kw):
        return database.build_database(p, **{**base, **kw})

    al = setup["materials"]["aluminium"]
    with pytest.raises(pp.Error, match="Scene binds its materials"):
        build(shapes={"s": pp.Scene(models.sphere(0.1, 1), al)})
    with pytest.raises(pp.Error, match="invalid shapes"):
        build(shapes={})
    with pytest.raises(pp.Error, match="invalid materials"):
        build(materials=[al])
    with pytest.raises(pp.Error, match="unit norm"):
        build(attitudes=[[1.0, 0.1, 0, 0]])
    with pytest.raises(pp.Error, match="chunk_attitudes"):
        build(chunk_attitudes=0)
    with pytest.raises(pp.Error, match="range_window"):
        build(range_window=0.05)  # the CubeSat needs +-0.36 m
    with pytest.raises(pp.Error, match=r"no material for part\(s\) \['edge'\]"):
        build(shapes={"plate": models.plate()}, materials={"m": {"front": al, "back": al}})
    with pytest.raises(pp.Error, match="has no parts"):
        build(shapes={"tri": (np.eye(3), np.array([[0, 1, 2]]))}, materials={"m": {"front": al}})
    with pytest.raises(pp.Error, match="sensor"):
        build(sensor="lidar")
    with pytest.raises(pp.Error, match="not a pprender database"):
        database.open_database(tmp_path)
    assert not p.exists()
    # a larger range_window pads with zeros
    ds = build(range_window=0.5)
    assert ds.sizes["range"] == 2 * int(np.ceil(0.5 / setup["sensor"].effective_bin_width()))
