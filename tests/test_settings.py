"""Render settings apart from the sensor's optics (issue 22): ``pprender.Settings`` given to
``render`` replaces the sensor's own, and equals the same keywords given to ``Lidar`` bit
for bit; the Lidar keeps taking them (its ``settings``)."""

from __future__ import annotations

import numpy as np
import pytest

import pprender
from pprender import models

SCENE = pprender.Scene(models.sphere(0.3, 2), pprender.Material("beckmann", alpha=0.3, eta=1.5))
Q = np.array([[1.0, 0, 0, 0], [0.8, 0.2, -0.4, 0.4]])
Q /= np.linalg.norm(Q, axis=1, keepdims=True)


@pytest.mark.parametrize("kw", [dict(quality="fast", resolution=32),
                                dict(resolution=24, pixel_samples=4, arithmetic="f64"),
                                dict(resolution=16, supersampling=2, brdf="shader", table={"n_z_double": 16})])
def test_settings_given_to_render_equal_the_lidar_keywords(kw) -> None:
    a = pprender.render(SCENE, pprender.Lidar(**kw), Q, outputs=("profile", "mueller"))
    b = pprender.render(SCENE, pprender.Lidar(), Q, outputs=("profile", "mueller"), settings=pprender.Settings(**kw))
    np.testing.assert_array_equal(a.profile, b.profile)
    np.testing.assert_array_equal(a.mueller, b.mueller)
    assert a.device == b.device
    assert pprender.Lidar(**kw).settings == pprender.Settings(**kw)


def test_settings_replace_the_sensors() -> None:
    sensor = pprender.Lidar(quality="accurate", resolution=64)
    r = pprender.render(SCENE, sensor, Q[:1], outputs=("profile", "mueller"), settings=pprender.Settings(resolution=20))
    assert r.mueller.shape[1:3] == (20, 20)


@pytest.mark.parametrize("kw, name", [(dict(quality="best"), "quality"), (dict(resolution=0), "resolution"),
                                      (dict(pixel_samples=3), "pixel_samples"), (dict(brdf="exact"), "brdf"),
                                      (dict(table={"n_z": 1}), "table"), (dict(arithmetic="f16"), "arithmetic"),
                                      (dict(coverage="analytic", pixel_samples=4), "pixel_samples"),
                                      (dict(supersampling="2"), "supersampling")])
def test_bad_settings_name_the_parameter(kw, name) -> None:
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        pprender.Settings(**kw)
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        pprender.Lidar(**kw)


def test_settings_of_another_type_are_refused() -> None:
    with pytest.raises(pprender.Error, match="settings"):
        pprender.render(SCENE, pprender.Lidar(resolution=16), Q, settings={"quality": "fast"})


def test_one_render_call_crosses_into_rust_once(monkeypatch) -> None:
    """A render is one call of the extension: attitudes go in as given (quaternions are
    converted in Rust, not sent out and back), and the tables' build time comes back with
    the result instead of through a separate ``prepare`` call."""
    scene = pprender.Scene(models.sphere(0.3, 2), pprender.Material("ggx", alpha=0.27, eta=1.4))

    class Counting:
        def __init__(self, inner) -> None:
            self.inner, self.calls = inner, []

        def __getattr__(self, name):
            attr = getattr(self.inner, name)
            if callable(attr):
                def call(*a, **k):
                    self.calls.append(name)
                    return attr(*a, **k)
                return call
            return attr

    proxy = Counting(scene._core)
    monkeypatch.setattr(scene, "_core", proxy)
    from pprender.lidar import dispatch

    monkeypatch.setattr(dispatch._core, "quaternions_to_rotations",
                        lambda *a: (_ for _ in ()).throw(AssertionError("round trip")))
    first = pprender.render(scene, pprender.Lidar(resolution=16), Q, outputs=("profile",))
    again = pprender.render(scene, pprender.Lidar(resolution=16), Q, outputs=("profile",))
    assert proxy.calls == ["render", "render"]
    assert first.table_seconds > 0 and again.table_seconds == 0.0
    np.testing.assert_array_equal(first.profile, again.profile)


@pytest.mark.parametrize("kw", [dict(), dict(arithmetic="f64"), dict(quality="reference")])
def test_progress_reports_and_an_exception_stops_the_render(kw) -> None:
    """``render(progress=...)``: called with (done, total) up to (N, N) on every backend;
    an exception raised in it stops the render and comes out of ``render``; the device and
    the scene render normally afterwards (the GPU path's error scopes were popped)."""
    sensor = pprender.Lidar(resolution=12, **kw)
    q = np.tile(Q[1], (6, 1))
    seen = []
    full = pprender.render(SCENE, sensor, q, outputs=("profile",), progress=lambda d, t: seen.append((d, t)))
    assert seen and seen[-1] == (6, 6) and all(t == 6 for _, t in seen)
    if not kw:  # a device reports chunk by chunk, in order (CPU workers may report out of order)
        assert [d for d, _ in seen] == sorted(d for d, _ in seen)

    class Stop(Exception):
        pass

    def stop(done, total):
        raise Stop(f"{done} of {total}")

    with pytest.raises(Stop):
        pprender.render(SCENE, sensor, q, outputs=("profile",), progress=stop)
    again = pprender.render(SCENE, sensor, q, outputs=("profile",))
    np.testing.assert_array_equal(again.profile, full.profile)
    with pytest.raises(pprender.Error, match="progress"):
        pprender.render(SCENE, sensor, q, progress=3)


@pytest.mark.parametrize("kw, stages", [
    (dict(), ["tables", "device context", "plan", "pipeline and buffers", "encode and submit", "device",
              "readback", "thin pixels (CPU)", "to NumPy"]),
    (dict(arithmetic="f64"), ["tables", "render", "to NumPy"]),
    (dict(quality="reference"), ["render", "to NumPy"]),
])
def test_stage_seconds_name_each_backends_stages_in_order(kw, stages) -> None:
    """``RenderResult.stage_seconds``: the benchmarks' diagnostic. Each backend's stages in
    the order they run, none negative, their sum within the call's wall-clock time (which
    adds only the Python-side checks and bookkeeping)."""
    import time

    scene = pprender.Scene(models.sphere(0.3, 2), pprender.Material("beckmann", alpha=0.35, eta=1.6))
    t = time.perf_counter()
    r = pprender.render(scene, pprender.Lidar(resolution=12, **kw), Q, outputs=("profile", "mueller"))
    wall = time.perf_counter() - t
    assert list(r.stage_seconds) == stages
    assert all(v >= 0.0 for v in r.stage_seconds.values())
    assert sum(r.stage_seconds.values()) <= wall
    if "tables" in stages:  # a new material: its tables are built in this call
        assert r.stage_seconds["tables"] == r.table_seconds > 0


def _request(**kw):
    base = dict(resolution=12, supersampling=1, samples=1, bistatic_angle=0.0, polarization=None,
                intensity_only=False, sigma_range=0.015, bin_width=0.005, image=True, range=False,
                profile=True, device="cpu")
    return pprender._core.RenderRequest(**{**base, **kw})


def test_one_request_object_crosses_into_rust() -> None:
    """The binding takes one ``_core.RenderRequest`` (checked when built) with the
    attitudes: reused for several calls and scenes, it renders what ``render`` does."""
    req = _request()
    assert "resolution=12" in repr(req)
    scene = pprender.Scene(models.sphere(0.3, 2), pprender.Material("beckmann", alpha=0.3, eta=1.5))
    a = scene._core.render(Q, req)
    b = scene._core.render(Q, req)
    np.testing.assert_array_equal(a["profile"], b["profile"])
    sensor = pprender.Lidar(resolution=12, pixel_samples=1, bin_width=0.005)
    c = scene._core.render(Q, _request(sigma_range=sensor.sigma_range))
    r = pprender.render(scene, sensor, Q, outputs=("profile", "mueller"), device="cpu")
    np.testing.assert_array_equal(r.profile.reshape(c["profile"].shape), c["profile"])


@pytest.mark.parametrize("kw, name", [(dict(resolution=0), "resolution"), (dict(bin_width=-1.0), "bin_width"),
                                      (dict(device="tpu"), "device"), (dict(samples=3), "samples"),
                                      (dict(pulse_samples=[1.0, 2.0], pulse_spacing=0.0), "pulse_spacing")])
def test_a_bad_request_is_refused_when_built(kw, name) -> None:
    with pytest.raises(pprender.Error, match=name):
        _request(**kw)
