"""pprender.plot: every function draws on small inputs (Agg backend) and returns a Figure
with the documented axes; the plotted data are checked where they come from a formula."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import StepPatch  # noqa: E402

import pprender  # noqa: E402
from pprender import instrument as ins  # noqa: E402
from pprender import models, plot  # noqa: E402

ATT = np.array([[math.cos(0.2), math.sin(0.2), 0.0, 0.0]])


@pytest.fixture(scope="module")
def renders():
    scene = pprender.Scene(models.plate(0.2, 0.1), pprender.Material("beckmann", alpha=0.3, eta=1.5 + 0j,
                                                                     terms=["single"]))
    mu = pprender.render(scene, pprender.Lidar(resolution=24), ATT, outputs=("profile", "mueller", "range"))
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
    # 2 channels: counts as steps, expected as lines
    assert len(fig.axes) == 1 and len(fig.axes[0].patches) == 2 and len(fig.axes[0].lines) == 2
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


def _gaussian_stokes(centre=0.3, sigma=0.01, edges=np.linspace(-1.0, 1.0, 401)):
    """A Stokes profile (B, 4): a Gaussian return of I = Q at ``centre`` (m), on ``edges``."""
    x = 0.5 * (edges[1:] + edges[:-1])
    i = np.exp(-0.5 * ((x - centre) / sigma) ** 2)
    return np.stack([i, i, 0 * i, 0 * i], axis=-1), edges


def test_profile_zooms_to_the_signal_and_shows_the_window_when_asked():
    """Default ``range_window="signal"``: the x-limits hold every bin above 1e-3 of the peak
    (for a Gaussian of sigma 1 cm, |x - x0| < sigma sqrt(2 ln 1000) = 3.72 cm, a hand value)
    padded by 4 bins (2 cm here, more than a tenth of the span), a tenth of the 2 m window;
    ``"all"`` shows the window, a pair shows itself."""
    p, edges = _gaussian_stokes()
    half = 0.01 * math.sqrt(2 * math.log(1000.0))
    width = edges[1] - edges[0]
    lo, hi = plot.profile(p, bin_edges=edges).axes[0].get_xlim()
    # lit bins: those whose centre is within `half`; the outer edge of the outermost is within
    # half a bin of 0.3 -/+ half; then 4 bins of pad
    assert abs(lo - (0.3 - half - 4 * width)) <= width / 2 + 1e-9
    assert abs(hi - (0.3 + half + 4 * width)) <= width / 2 + 1e-9
    assert hi - lo < 0.1 * (edges[-1] - edges[0])
    assert plot.profile(p, bin_edges=edges, range_window="all").axes[0].get_xlim() == (-1.0, 1.0)
    assert plot.profile(p, bin_edges=edges, range_window=(0.1, 0.5)).axes[0].get_xlim() == (0.1, 0.5)
    # no signal at all: the whole window
    assert plot.profile(0 * p, bin_edges=edges).axes[0].get_xlim() == (-1.0, 1.0)


def test_profile_zoom_of_a_render_and_of_a_measurement(renders):
    """A compact target (the 20 x 10 cm plate) fills a small part of its render's window; the
    zoomed limits hold every bin above 1 % of the peak. A measurement zooms on its expected
    signal, not on the background spread over every bin."""
    mu, _ = renders
    window = mu.bin_edges[-1] - mu.bin_edges[0]
    i = mu.profile[0, :, 0, 0] + mu.profile[0, :, 0, 1]
    lit = np.flatnonzero(i > 0.01 * i.max())
    lo, hi = plot.profile(mu).axes[0].get_xlim()
    assert lo <= mu.bin_edges[lit[0]] and hi >= mu.bin_edges[lit[-1] + 1]
    assert hi - lo < 0.6 * window
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=10**5, background_rate=1e7)
    meas = ins.measure(mu, inst.scaled_to(300, mu), seed=0)
    assert meas.background.sum() > 10  # background counts in the bins far from the signal
    lo_m, hi_m = plot.profile(meas).axes[0].get_xlim()
    assert lo_m <= mu.bin_edges[lit[0]] and hi_m >= mu.bin_edges[lit[-1] + 1]
    assert hi_m - lo_m < 0.6 * window


def test_profile_expected_lines_drawn_over_the_counts(renders):
    """The expectation is drawn above the counts (higher zorder), as lines through the bin
    centres holding ``Measurement.expected``, and both are in the legend."""
    mu, _ = renders
    meas = ins.measure(mu, ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=10**5).scaled_to(300, mu),
                       seed=0)
    ax = plot.profile(meas).axes[0]
    counts = [a for a in ax.patches if isinstance(a, StepPatch)]
    expected = [a for a in ax.lines if isinstance(a, Line2D)]
    assert len(counts) == len(expected) == 2
    assert min(e.get_zorder() for e in expected) > max(c.get_zorder() for c in counts)
    for c, line in enumerate(expected):
        np.testing.assert_allclose(line.get_xdata(), meas.range_axis, rtol=0, atol=1e-15)
        np.testing.assert_allclose(line.get_ydata(), meas.expected[0, :, c], rtol=1e-12)
        np.testing.assert_array_equal(counts[c].get_data().values, meas.counts[0, :, c])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["co counts", "co expected", "cross counts", "cross expected"]


def test_profile_bad_range_window(renders):
    mu, _ = renders
    for bad in ("whole", None, (0.2, 0.1), (0.0, float("nan")), (0.0, 1.0, 2.0), ("a", "b"), 0.3):
        with pytest.raises(pprender.Error, match=r"range_window = .*\"signal\".*\"all\".*lo < hi"):
            plot.profile(mu, range_window=bad)


def test_range_image(renders):
    """The range map is shown as is, masked where it is NaN (nothing seen), over the image
    extent, with a colorbar in metres."""
    mu, st = renders
    fig = plot.range_image(mu)
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # image + colorbar
    shown = fig.axes[0].images[0].get_array()
    r = mu.range[0]
    assert np.isnan(r).any() and np.isfinite(r).any()  # the plate does not fill its window
    np.testing.assert_array_equal(np.ma.getmaskarray(shown), np.isnan(r))
    np.testing.assert_array_equal(shown.compressed(), r[np.isfinite(r)])
    assert fig.axes[0].images[0].get_extent() == [-mu.extent, mu.extent, -mu.extent, mu.extent]
    assert "(m)" in fig.axes[1].get_ylabel()
    fig2, axes = plt.subplots(1, 2)
    assert plot.range_image(mu, index=-1, ax=axes[1]) is fig2
    with pytest.raises(pprender.Error, match=r'no range map; render with outputs=\("range",\)'):
        plot.range_image(st)
    with pytest.raises(pprender.Error, match=r"index = 1: an integer in \[-1, 1\)"):
        plot.range_image(mu, index=1)
    with pytest.raises(pprender.Error, match="RenderResult"):
        plot.range_image(mu.range)


def _load_demo():
    path = Path(__file__).resolve().parents[1] / "examples" / "demo.py"
    spec = importlib.util.spec_from_file_location("pprender_demo", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _titles_inside(fig):
    """Every axes title and the suptitle lie inside the figure, once drawn (pixels)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    texts = [ax.title for ax in fig.axes if ax.get_title()]
    if fig._suptitle is not None:
        texts.append(fig._suptitle)
    assert texts
    box = fig.bbox
    for t in texts:
        b = t.get_window_extent(renderer)
        assert b.x0 >= box.x0 - 0.5 and b.x1 <= box.x1 + 0.5 and b.y0 >= box.y0 - 0.5 and b.y1 <= box.y1 + 0.5, \
            (t.get_text(), b, box)


def test_titles_inside_the_figures(renders):
    """The image helpers' titles and the demo's Mueller figures' titles (a material's repr
    once ran off both sides) are inside the figure."""
    mu, _ = renders
    for fig in (plot.polarization_images(mu), plot.range_image(mu)):
        _titles_inside(fig)
    # white paint has the demo's longest title (its diffuse albedo too)
    fig = _load_demo().mueller_figure("white_paint", pprender.materials.get("white_paint", wavelength=1064e-9))
    assert "white_paint" in fig._suptitle.get_text()
    _titles_inside(fig)
