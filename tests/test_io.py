"""Saving and loading RenderResult and Measurement (Zarr v3 and netCDF through xarray).

References are independent of the code under test: the objects themselves (round trips
compared byte for byte with ``ndarray.tobytes``, scalars with ``==``, dataclass
equality for the Instrument), ``pprender.measure`` and ``ForwardModel.log_likelihood``
run on the original and the loaded objects, and for the image coordinates a box placed
off the body origin at a known position (its coverage-weighted centroid in ``x``, ``y``).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import pprender
from pprender import RenderResult, fit, models
from pprender import instrument as ins

SUFFIXES = (".zarr", ".nc")
LIDAR = pprender.Lidar(resolution=16, pixel_samples=1)
UNIT_Q = np.array([[0.9, 0.3, 0.2, 0.24]]) / np.linalg.norm([0.9, 0.3, 0.2, 0.24])


def same_array(a, b) -> bool:
    """Bit for bit: dtype, shape and bytes."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def assert_same_result(a: RenderResult, b: RenderResult) -> None:
    for f in ("cross_section", "bin_edges", "profile", "mueller", "stokes", "intensity", "range", "coverage"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert same_array(x, y), f
    for f in ("pixel_size", "extent", "device", "table_seconds", "wavelength", "stage_seconds"):
        assert getattr(a, f) == getattr(b, f), f
    assert list(a.stage_seconds) == list(b.stage_seconds)  # order kept
    assert json.dumps(a.extra) == json.dumps(b.extra)  # equal, NaN included
    assert (a.by_bounce is None) == (b.by_bounce is None)
    if a.by_bounce is not None:
        assert list(a.by_bounce) == list(b.by_bounce)
        for k in a.by_bounce:
            assert same_array(a.by_bounce[k], b.by_bounce[k]), k


def assert_same_measurement(a: ins.Measurement, b: ins.Measurement) -> None:
    for f in ("counts", "expected", "signal", "background", "bin_edges"):
        assert same_array(getattr(a, f), getattr(b, f)), f
    assert b.channel_names == a.channel_names and type(b.channel_names) is tuple
    assert b.instrument == a.instrument
    assert b.seed == a.seed and type(b.seed) is type(a.seed)
    assert json.dumps(a.extra) == json.dumps(b.extra)


@pytest.fixture(scope="module")
def rendered() -> RenderResult:
    scene = pprender.Scene(models.sphere(0.2), "aluminium")
    q = np.array([[1.0, 0.0, 0.0, 0.0], [0.8, 0.6, 0.0, 0.0]])
    return pprender.render(scene, LIDAR, q, outputs=("profile", "mueller", "range"))


def hand_built(kind: str) -> RenderResult:
    """A result assembled by hand: Stokes or intensity-only, by_bounce, awkward values."""
    rng = np.random.default_rng(5)
    pol = {"stokes": (4,), "intensity": ()}[kind]
    n, k, b, h, w = 3, 2, 5, 4, 6
    cs = rng.standard_normal((n,) + pol)
    cs.flat[0] = -0.0
    cs.flat[1] = np.nan
    img = rng.standard_normal((n, h, w) + pol).astype(np.float32)
    rmap = rng.standard_normal((n, h, w)).astype(np.float32)
    rmap[0, 0, :] = np.nan
    bounce = {
        "cross_section": rng.standard_normal((n, k) + pol),
        "profile": rng.standard_normal((n, k, b) + pol),
        kind: rng.standard_normal((n, k, h, w) + pol).astype(np.float32),
    }
    return RenderResult(
        cross_section=cs,
        bin_edges=np.linspace(-0.3, 0.3, b + 1),
        pixel_size=0.1,
        extent=0.3,
        device="by hand",
        profile=rng.standard_normal((n, b) + pol),
        range=rmap,
        coverage=rng.uniform(size=(n, h, w)).astype(np.float32),
        table_seconds=0.25,
        stage_seconds={"render": 1.5, "to NumPy": 1e-300},
        by_bounce=bounce,
        extra={"note": "ünïcode", "n": 2**70, "x": [0.1, -0.0, float("inf"), float("nan")],
               "nested": {"a": [1, None, True]}},
        wavelength=None,
        **{kind: img},
    )


# ---------------------------------------------------------------------- RenderResult


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_rendered_result_round_trip_is_exact(rendered, tmp_path, suffix):
    path = tmp_path / f"r{suffix}"
    rendered.save(path)
    back = RenderResult.load(str(path))
    assert_same_result(rendered, back)
    assert back.stokes is None and back.intensity is None and back.by_bounce is None
    assert back.wavelength == LIDAR.wavelength and back.extra == {}


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("kind", ["stokes", "intensity"])
def test_hand_built_result_round_trip_is_exact(tmp_path, suffix, kind):
    res = hand_built(kind)
    res.save(tmp_path / f"h{suffix}")
    back = RenderResult.load(tmp_path / f"h{suffix}")
    assert_same_result(res, back)
    assert back.wavelength is None and back.mueller is None
    assert np.signbit(back.cross_section.flat[0]) and np.isnan(back.cross_section.flat[1])
    assert back.extra["n"] == 2**70 and np.signbit(back.extra["x"][1])


def test_result_layout(rendered):
    ds = rendered.to_xarray()
    assert ds.attrs["format"] == "pprender.RenderResult/1"
    assert ds.attrs["pprender_version"] == pprender.__version__
    assert ds.attrs["wavelength"] == LIDAR.wavelength
    assert ds["profile"].dims == ("attitude", "range", "mueller_row", "mueller_col")
    assert ds["mueller_image"].dims == ("attitude", "row", "col", "mueller_row", "mueller_col")
    assert ds["range_image"].dims == ("attitude", "row", "col")
    assert ds["profile"].attrs["units"] == "m2" and ds["range"].attrs["units"] == "m"
    np.testing.assert_array_equal(ds["range"].values, rendered.range_axis)
    np.testing.assert_array_equal(ds["time"].values, rendered.time_axis)
    # the layout is what a user selects by: the profile of attitude 1, Mueller 0,0
    np.testing.assert_array_equal(ds["profile"].sel(attitude=1, mueller_row=0, mueller_col=0),
                                  rendered.profile[1, :, 0, 0])
    # a dataset whose dimensions were reordered still gives the same result
    assert_same_result(rendered, RenderResult.from_xarray(ds.transpose(*reversed(list(ds.dims)))))


def test_image_coordinates_place_an_off_centre_box():
    """x (columns) and y (rows) are the pixel centres in the telescope frame: a 0.1 m box
    centred at (0.3, 0.15, 0) in the body frame, identity attitude, is seen as a square
    whose coverage-weighted centroid is (0.3, 0.15) (within a quarter pixel: the square
    spans whole pixels up to its edges' partial coverage)."""
    import trimesh

    box = trimesh.creation.box((0.1, 0.1, 0.1))
    box.apply_translation((0.3, 0.15, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pprender.OffCentreWarning)
        res = pprender.render(pprender.Scene(box, "aluminium"), pprender.Lidar(resolution=32),
                              np.array([[1.0, 0.0, 0.0, 0.0]]), outputs=("range",))
    ds = res.to_xarray()
    cov = ds["coverage"].isel(attitude=0)
    x0 = float((cov * ds["x"]).sum() / cov.sum())
    y0 = float((cov * ds["y"]).sum() / cov.sum())
    assert x0 == pytest.approx(0.3, abs=0.25 * res.pixel_size)
    assert y0 == pytest.approx(0.15, abs=0.25 * res.pixel_size)
    assert float(cov.sum()) * res.pixel_size**2 == pytest.approx(0.01, rel=0.05)


def test_loaded_result_measures_identically(rendered, tmp_path):
    inst = pprender.Instrument(pulse_energy=1e-4, target_range=500e3, jitter=20e-12, background_rate=1e4,
                               n_pulses=10_000)
    rendered.save(tmp_path / "r.zarr")
    back = RenderResult.load(tmp_path / "r.zarr")
    a = pprender.measure(rendered, inst, seed=11)
    b = pprender.measure(back, inst, seed=11)
    assert_same_measurement(a, b)
    assert a.counts.sum() > 0


# ---------------------------------------------------------------------- Measurement


@pytest.fixture(scope="module")
def measured(rendered) -> ins.Measurement:
    inst = pprender.Instrument(pulse_energy=1e-4, target_range=500e3, channels="stokes", jitter=30e-12,
                               background_rate=[1e4, 2e4, 0, 1, 2, 3.5], n_pulses=7, beam="tophat")
    m = pprender.measure(rendered, inst, seed=2**40 + 3)
    m.extra = {"observer": "test", "snr": [1.5, 2.0]}
    return m


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_measurement_round_trip_is_exact(measured, tmp_path, suffix):
    measured.save(tmp_path / f"m{suffix}")
    back = ins.Measurement.load(tmp_path / f"m{suffix}")
    assert_same_measurement(measured, back)
    assert back.counts.dtype == np.int64 and back.counts.ndim == 3
    assert back.instrument.channels == measured.instrument.channels  # Channels in full
    np.testing.assert_array_equal(back.snr, measured.snr)


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_measurement_shapes_and_no_seed(tmp_path, suffix):
    """One measurement (no leading axis), and two leading axes; seed None stays None."""
    rng = np.random.default_rng(0)
    inst = pprender.Instrument(pulse_energy=1, target_range=1e3, channels=ins.Channels(
        ("a", "b"), ((0.5, 0.5, 0, 0), (1.0, 0, 0, 0)), ((1, 0, 0, 1),) * 2, (0.3, 1.0), (1.0, 0.5), "custom"))
    e = np.array([0.0, 0.5, 1.25])
    for lead in ((), (2, 3)):
        lam = rng.uniform(0, 5, lead + (2, 2))
        m = ins.Measurement(counts=rng.poisson(lam).astype(np.int64), expected=lam, signal=lam / 2,
                            background=np.ones((2, 2)), bin_edges=e, channel_names=("a", "b"), instrument=inst)
        p = tmp_path / f"m{len(lead)}{suffix}"
        m.save(p)
        back = ins.Measurement.load(p)
        assert_same_measurement(m, back)
        assert back.seed is None


def test_measurement_layout(measured):
    ds = measured.to_xarray()
    assert ds.attrs["format"] == "pprender.Measurement/1"
    assert ds["counts"].dims == ("attitude", "range", "channel")
    assert list(ds["channel"].values) == ["H", "V", "D", "A", "R", "L"]
    assert ds.attrs["wavelength"] == measured.instrument.wavelength
    assert json.loads(ds.attrs["instrument"])["n_pulses"] == 7
    np.testing.assert_array_equal(ds["bin_edges"].values, measured.bin_edges)


def test_loaded_measurement_fits_identically(tmp_path):
    """ForwardModel's Poisson log-likelihood of the loaded measurement equals the original's,
    with the original instrument and with the loaded one."""
    mesh = models.cubesat("1U", panels=None, antenna=False, detail=0)
    metal = pprender.Material("beckmann", alpha=0.3, eta=1.38 + 10.2j, terms=["single"])
    lid = pprender.Lidar(resolution=16, pixel_samples=1)
    truth = pprender.render(pprender.Scene(mesh, metal), lid, UNIT_Q,
                            outputs=("profile",))
    inst = pprender.Instrument(pulse_energy=1.0, target_range=1e3, jitter=10e-12, background_rate=1e5,
                               n_pulses=100_000)
    inst = inst.scaled_to(2e3, truth)
    meas = pprender.measure(truth, inst, seed=4)[0]
    meas.save(tmp_path / "m.nc")
    back = ins.Measurement.load(tmp_path / "m.nc")
    theta = np.array([[0.4, 1.0], [0.5, 1.1]])
    models_ = [fit.ForwardModel(mesh, metal, i, e, ("rx", "scale"), lidar=lid, fixed={"ry": 0.3, "rz": 0.2})
               for i, e in ((inst, meas.bin_edges), (back.instrument, back.bin_edges))]
    ll = models_[0].log_likelihood(theta, meas)
    assert np.all(np.isfinite(ll))
    np.testing.assert_array_equal(models_[0].log_likelihood(theta, back), ll)
    np.testing.assert_array_equal(models_[1].log_likelihood(theta, back), ll)


# ---------------------------------------------------------------------- refusals


def test_suffix_picks_the_format(rendered, tmp_path):
    with pytest.raises(pprender.Error, match=r"r\.h5.*'\.zarr'.*'\.nc'"):
        rendered.save(tmp_path / "r.h5")
    with pytest.raises(pprender.Error, match="suffix"):
        RenderResult.load(tmp_path / "r")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_overwrite(rendered, measured, tmp_path, suffix):
    p = tmp_path / f"x{suffix}"
    measured.save(p)
    with pytest.raises(pprender.Error, match="exists.*overwrite=True"):
        rendered.save(p)
    assert ins.Measurement.load(p).seed == measured.seed  # untouched
    rendered.save(p, overwrite=True)  # a pprender file is replaced
    assert_same_result(rendered, RenderResult.load(p))
    assert sorted(q.name for q in tmp_path.iterdir()) == [p.name]  # no temporary left


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_overwrite_never_replaces_other_things(rendered, tmp_path, suffix):
    p = tmp_path / f"y{suffix}"
    if suffix == ".zarr":
        p.mkdir()
        (p / "precious.txt").write_text("keep")
    else:
        p.write_text("keep")
    with pytest.raises(pprender.Error, match="replaces only saved"):
        rendered.save(p, overwrite=True)
    assert (p / "precious.txt" if suffix == ".zarr" else p).read_text() == "keep"


def test_overwrite_never_replaces_a_database(rendered, tmp_path):
    """A candidate database (its format attribute, as pprender.database writes it) is
    pprender's but not replaceable by a result; loading it as one points to open_database."""
    import xarray as xr

    p = tmp_path / "cands.zarr"
    xr.Dataset({"profile": ("x", np.zeros(2))}, attrs={"format": "pprender.database/1"}).to_zarr(
        p, zarr_format=3, consolidated=False)
    with pytest.raises(pprender.Error, match="replaces only saved"):
        rendered.save(p, overwrite=True)
    with pytest.raises(pprender.Error, match="database, not a RenderResult.*open_database"):
        RenderResult.load(p)
    assert xr.open_zarr(p, consolidated=False).attrs["format"] == "pprender.database/1"


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_load_refuses_what_is_not_ours(rendered, measured, tmp_path, suffix):
    import xarray as xr

    other = tmp_path / f"other{suffix}"
    plain = xr.Dataset({"a": ("x", np.arange(3.0))})
    if suffix == ".zarr":
        plain.to_zarr(other, zarr_format=3, consolidated=False)
    else:
        plain.to_netcdf(other)
    with pytest.raises(pprender.Error, match="not a pprender RenderResult"):
        RenderResult.load(other)
    with pytest.raises(pprender.Error, match="nothing there"):
        RenderResult.load(tmp_path / f"missing{suffix}")
    measured.save(tmp_path / f"m{suffix}")
    with pytest.raises(pprender.Error, match="Measurement, not a RenderResult"):
        RenderResult.load(tmp_path / f"m{suffix}")
    rendered.save(tmp_path / f"r{suffix}")
    with pytest.raises(pprender.Error, match="RenderResult, not a Measurement"):
        ins.Measurement.load(tmp_path / f"r{suffix}")


def test_newer_format_is_refused(rendered, measured):
    for obj in (rendered, measured):
        ds = obj.to_xarray()
        ds.attrs["format"] = ds.attrs["format"].replace("/1", "/9")  # beyond every reader
        with pytest.raises(pprender.Error, match="newer pprender"):
            type(obj).from_xarray(ds)
    with pytest.raises(pprender.Error, match="ds"):
        RenderResult.from_xarray({"format": "pprender.RenderResult/1"})


@pytest.mark.parametrize(
    "value, hint",
    [(np.float64(1.0), "NumPy"), ((1, 2), "tuple"), (object(), "object"), ({1: "a"}, "key"),
     (np.zeros(2), "NumPy")],
)
def test_unserializable_extra_names_the_key(rendered, measured, tmp_path, value, hint):
    for obj in (rendered, measured):
        saved = obj.extra
        obj.extra = {**saved, "bad_key": value}
        try:
            with pytest.raises(pprender.Error, match=rf"extra\['bad_key'\].*{hint}|extra.*{hint}"):
                obj.save(tmp_path / "e.zarr")
        finally:
            obj.extra = saved
    assert not any(tmp_path.iterdir())


def test_netcdf_refuses_counts_it_cannot_store(measured, tmp_path):
    """scipy's netCDF3 (the engine installed here) has no int64: counts above 2**31 - 1 are
    refused for .nc, naming the path and .zarr, and nothing is left behind; .zarr stores them."""
    import importlib.util

    big = ins.Measurement(**{**measured.__dict__, "counts": measured.counts + 2**40})
    if importlib.util.find_spec("netCDF4") is None and importlib.util.find_spec("h5netcdf") is None:
        with pytest.raises(pprender.Error, match=r"big\.nc.*'\.zarr'"):
            big.save(tmp_path / "big.nc")
        assert not any(tmp_path.iterdir())
    big.save(tmp_path / "big.zarr")
    assert same_array(ins.Measurement.load(tmp_path / "big.zarr").counts, big.counts)


def test_bad_shapes_name_the_field(rendered):
    bad = RenderResult(**{**rendered.__dict__, "profile": rendered.profile[:, :-1]})
    with pytest.raises(pprender.Error, match="RenderResult.profile"):
        bad.to_xarray()
    with pytest.raises(pprender.Error, match="directory"):
        rendered.save(Path("/nonexistent-dir-pprender/r.zarr"))
