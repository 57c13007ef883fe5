"""pprender.plot: every function draws on small inputs (Agg backend) and returns a Figure
with the documented axes; the plotted data are checked where they come from a formula."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import pprender  # noqa: E402
from pprender import instrument as ins  # noqa: E402
from pprender import models, plot  # noqa: E402

ATT = np.array([[math.cos(0.2), math.sin(0.2), 0.0, 0.0]])


@pytest.fixture(scope="module")
def renders():
    scene = pprender.Scene(models.plate(0.2, 0.1), pprender.Material("beckmann", alpha=0.3, eta=1.5 + 0j,
                                                                     terms=["single"]))
    mu = pprender.render(scene, pprender.Lidar(resolution=24), ATT, outputs=("profile", "mueller"))
    st = pprender.render(scene, pprender.Lidar(resolution=24, polarization=[1, 1, 0, 0]), ATT,
                         outputs=("profile", "stokes"))
    return mu, st


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def test_stokes_images(renders):
    mu, st = renders
    for r in (mu, st):
        fig = plot.stokes_images(r)
        assert isinstance(fig, Figure) and len(fig.axes) == 8  # 4 images + 4 colorbars
    # the Q/I panel shows M s_in / I for the default H input: check one pixel against the matrix
    fig = plot.stokes_images(mu)
    q_over_i = fig.axes[1].images[0].get_array()
    m = mu.mueller[0]
    s = m @ np.array([1.0, 1.0, 0.0, 0.0])
    iy, ix = np.unravel_index(np.argmax(s[..., 0]), s.shape[:2])
    assert q_over_i[iy, ix] == pytest.approx(s[iy, ix, 1] / s[iy, ix, 0], rel=1e-12)
    assert len(plot.stokes_images(st, normalized=False).axes) == 8
    with pytest.raises(pprender.Error, match="image"):
        plot.stokes_images(pprender.render(pprender.Scene(models.plate(0.2, 0.1), "aluminium"),
                                           pprender.Lidar(resolution=8), ATT, outputs=("profile",)))
    with pytest.raises(pprender.Error, match="index"):
        plot.stokes_images(mu, index=3)


def test_polarization_images(renders):
    mu, st = renders
    assert len(plot.polarization_images(mu).axes) == 8  # DoP, DoLP, DoCP, depolarization index
    assert len(plot.polarization_images(st).axes) == 6  # no Mueller matrix: no depolarization index
    with pytest.raises(pprender.Error, match="input_state"):
        plot.polarization_images(mu, input_state=[1, 2, 0, 0])


def test_profile_from_renders_arrays_and_measurements(renders):
    mu, st = renders
    fig = plot.profile(mu)
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    # the I line is the (H-input) Stokes I = M00 + M01 of the profile
    i_line = fig.axes[0].patches[0].get_data().values
    np.testing.assert_allclose(i_line, mu.profile[0, :, 0, 0] + mu.profile[0, :, 0, 1], rtol=1e-12)
    assert len(plot.profile(st.profile, bin_edges=st.bin_edges, log=True).axes) == 1
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5, channels="stokes")
    assert len(plot.profile(mu, instrument=inst).axes[0].patches) == 6
    meas = ins.measure(mu, ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=10**5).scaled_to(300, mu), seed=0)
    fig = plot.profile(meas)
    assert len(fig.axes) == 1 and len(fig.axes[0].patches) == 4  # counts and expected, 2 channels
    fig, ax = plt.subplots(1, 2)
    assert plot.profile(meas[0], ax=ax[1]) is fig
    with pytest.raises(pprender.Error, match="bin_edges"):
        plot.profile(mu.profile)


def test_confusion_matrix():
    m = np.array([[8, 2, 0], [1, 7, 2], [0, 0, 10]])
    fig = plot.confusion_matrix(m, ["sphere", "plate", "cubesat"])
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # matrix + colorbar
    shown = fig.axes[0].images[0].get_array()
    np.testing.assert_allclose(shown.sum(axis=1), 1.0)  # row fractions
    assert [t.get_text() for t in fig.axes[0].texts][:3] == ["8", "2", "0"]
    with pytest.raises(pprender.Error, match="square"):
        plot.confusion_matrix(np.ones((2, 3)), ["a", "b"])
    with pytest.raises(pprender.Error, match="labels"):
        plot.confusion_matrix(m, ["a", "b"])
    with pytest.raises(pprender.Error, match=">= 0"):
        plot.confusion_matrix(-m, ["a", "b", "c"])


def test_attitude_error_histogram(rng):
    err = np.abs(rng.normal(0.0, 0.01, size=200))
    fig = plot.attitude_errors(err)
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    # the median line sits at the median in degrees
    x = fig.axes[0].lines[0].get_xdata()[0]
    assert x == pytest.approx(np.degrees(np.median(err)), rel=1e-12)
    with pytest.raises(pprender.Error, match="errors"):
        plot.attitude_errors([-0.1, 0.2])


def test_corner_plot(rng):
    samples = rng.normal(size=(500, 3)) * [0.01, 0.1, 1.0] + [0.4, 1.0, 5.0]
    fig = plot.corner(samples, names=["rx", "scale", "alpha"], truths=[0.4, 1.0, 5.0])
    assert isinstance(fig, Figure) and len(fig.axes) == 9  # p x p grid
    assert len(plot.corner(samples[:, 0]).axes) == 1
    with pytest.raises(pprender.Error, match="names"):
        plot.corner(samples, names=["a"])


def test_index_counts_from_the_end_and_the_message_says_so(renders):
    """A negative ``index`` selects from the end (as NumPy does) and the error's range says
    so; a bool is not an index."""
    mu, _ = renders
    n = len(mu.mueller)
    last = plot.stokes_images(mu, index=-1, normalized=False).axes[0].images[0].get_array()
    np.testing.assert_allclose(last, plot.stokes_images(mu, index=n - 1, normalized=False).axes[0].images[0].get_array())
    for bad in (n, -n - 1, True, 1.0):
        with pytest.raises(pprender.Error, match=rf"index = .*\[-{n}, {n}\) \(negative counts from the end\)"):
            plot.stokes_images(mu, index=bad)
    with pytest.raises(pprender.Error, match=r"\[-2, 2\) \(negative counts from the end\)"):
        plot.profile(np.ones((2, 5, 4)), bin_edges=np.arange(6.0), index=2)
