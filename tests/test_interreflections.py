"""Inter-reflections between parts (``bounces`` 2 and 3): against Mitsuba 3 (a live render
of a rough-aluminium dihedral, and the committed references of
``benchmarks/mitsuba_corners.py``), the outputs split by bounces, the random numbers
(batches, seeds, backends) and bad input. The core's own tests (analytic view factor,
the perfect-conductor dihedral's Mueller matrix, the edge range) are in
``src/render/paths/tests.rs``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import mitsuba_corners as mc
import pprender
from pprender import models

ROOT = Path(__file__).resolve().parents[1]
ALUMINIUM = complex(1.3763, 10.2449)


def aluminium(alpha: float) -> pprender.Material:
    """The single-term Beckmann conductor that Mitsuba's ``roughconductor`` evaluates (Smith
    masking with Walter's G1, uncorrelated)."""
    return pprender.Material("beckmann", alpha=alpha, eta=ALUMINIUM, shadowing="smith",
                             correlation="none", smith_g1="walter", terms=("single",))


def corner_render(mesh, alpha, rotations, resolution=48, path_samples=32, seed=0, outputs=("profile",),
                  **kw):
    sc = pprender.Scene(mesh, aluminium(alpha))
    lidar = pprender.Lidar(resolution=resolution, bounces=3, path_samples=path_samples, path_seed=seed,
                           polarization=[1, 0, 0, 0], arithmetic="f64", **kw)
    return pprender.render(sc, lidar, np.asarray(rotations).reshape(-1, 3, 3), outputs=outputs)


def test_dihedral_second_bounce_matches_a_live_mitsuba_render(mitsuba):
    """A 0.3 m dihedral of rough aluminium (alpha 0.3) seen 20 deg off its axis: the
    2-bounce cross-section (Mitsuba ``max_depth`` 3 minus 2, same seed: the double part with
    its own noise) and its S1/S0 agree within 4 combined standard errors plus 0.5% (the
    committed sweep agrees to 0.1%, docs/interreflections.md), and the one-bounce parts agree
    to 0.5% (the backend against Mitsuba's single scattering)."""
    mesh = mc.dihedral()
    rot = mc.dihedral_rotation(20.0)
    res, spp = 48, 64
    t2 = [mc.mitsuba_totals(mesh, mc.roughconductor(0.3), rot, 2, spp, res, seed)[0] for seed in (1, 2)]
    t3 = [mc.mitsuba_totals(mesh, mc.roughconductor(0.3), rot, 3, spp, res, seed)[0] for seed in (1, 2)]
    double = [b - a for a, b in zip(t2, t3)]
    mit = 0.5 * (double[0] + double[1])
    mit_se = abs(double[0][0] - double[1][0]) / 2 + 1e-3 * mit[0]  # two seeds: a rough bound
    ours = [corner_render(mesh, 0.3, rot, resolution=res, seed=s).by_bounce["cross_section"][0] for s in (0, 1)]
    b2 = 0.5 * (ours[0][1] + ours[1][1])
    our_se = abs(ours[0][1][0] - ours[1][1][0]) / 2
    assert mit[0] > 0.3  # the double bounce dominates here (single 0.13 m^2)
    tol = 4 * math.hypot(mit_se, our_se) + 5e-3 * mit[0]
    assert abs(b2[0] - mit[0]) < tol, (b2, mit, mit_se, our_se)
    assert abs(b2[1] / b2[0] - mit[1] / mit[0]) < 2e-3, (b2, mit)
    single = 0.5 * (t2[0] + t2[1])
    assert abs(ours[0][0][0] / single[0] - 1) < 5e-3


def test_dihedral_stokes_images_match_mitsuba_pixel_by_pixel(mitsuba):
    """The first Mueller column as images (unpolarized transmit, S0 and S1), one and two
    bounces (Mitsuba ``max_depth`` 3), the rough-aluminium dihedral (alpha 0.3) 20 and 35
    deg across its opening, 48 x 48: the pixels agree within their noise. Each renderer is
    the mean of two seeds; the variance of that mean per pixel is ``(a - b)^2 / 4``. The
    statistic ``R = sum (pprender - Mitsuba)^2 / sum (var_pprender + var_Mitsuba)`` over
    the pixels either sees is 1 for images that differ by noise alone (measured 0.97-1.05
    here); it must be under 1.3 (about 5 of its standard deviations over ~600 pixels, with
    the variance estimates' heavy tails). The same images mirrored left-right give R = 7
    to 300: a misplaced pixel would show. pprender uses analytic coverage (its one-bounce
    part has no sampling error at the plates' edges)."""
    mesh = mc.dihedral()
    res, spp, paths = 48, 64, 32
    delta = 2.0 * mc.extent(mesh) / res
    sc = pprender.Scene(mesh, aluminium(0.3))
    for theta in (20.0, 35.0):
        rot = mc.dihedral_rotation(theta)
        a, b = (4.0 * math.pi * delta**2 * mc.mitsuba_totals(mesh, mc.roughconductor(0.3), rot, 3, spp, res, seed,
                                                              return_images=True)[1][0].astype(np.float64)
                for seed in (1, 2))
        p0, p1 = (pprender.render(sc, pprender.Lidar(resolution=res, bounces=2, path_samples=paths, path_seed=seed,
                                                     polarization=[1, 0, 0, 0], arithmetic="f64", coverage="analytic"),
                                  rot[None], outputs=("stokes",)).stokes[0] for seed in (0, 1))
        m, p = (a + b) / 2, (p0 + p1) / 2
        var = (a - b) ** 2 / 4 + (p0 - p1) ** 2 / 4
        seen = (m[..., 0] > 0) | (p[..., 0] > 0)
        assert seen.sum() > 400
        for c in (0, 1):
            r = np.sum((p - m)[seen, c] ** 2) / np.sum(var[seen, c])
            mirrored = np.sum((p[:, ::-1] - m)[seen, c] ** 2) / np.sum(var[seen, c])
            assert 0.5 < r < 1.3, (theta, c, r)
            assert mirrored > 5.0, (theta, c, mirrored)


@pytest.fixture(scope="module")
def corners() -> dict:
    return json.loads((ROOT / "docs/data/mitsuba-corners.json").read_text())


def test_corner_sweep_matches_the_committed_mitsuba_references(corners):
    """The committed Mitsuba sweep (``benchmarks/mitsuba_corners.py --write``; 1024 spp,
    128 x 128): the dihedral at alpha 0.3 across its opening and tilted out of it, and the
    trihedral (alpha 0.05) 0, 10 and 20 deg off its axis. Where a bounce order carries more
    than 5% of the total, pprender's (64 x 64, 64 paths per pixel) is within 2% of
    Mitsuba's for the second bounce and 8% for the third, the totals within 2% (this
    render's noise, the standard deviation over 6 seeds: 0.3% of the trihedral's triple
    bounce at 10 deg; Mitsuba's is under 0.1%)."""
    checked = 0
    for s in corners["summary"]:
        if not (s["mesh"] == "trihedral" or (s["alpha"] == 0.3 and s["theta_deg"] in (0.0, 20.0, 40.0))):
            continue
        mesh = mc.dihedral() if s["mesh"] == "dihedral" else mc.trihedral()
        entry = next(e for e in corners["entries"] if e["mesh"] == s["mesh"] and e["bsdf"]["alpha"] == s["alpha"]
                     and e["view"] == {k: s[k] for k in e["view"]})
        r = corner_render(mesh, s["alpha"], np.asarray(entry["rotation"]), resolution=64, path_samples=64)
        ours = r.by_bounce["cross_section"][0, :, 0]
        theirs = np.array([s["single_S0"], s["double_S0"], s["triple_S0"]])
        total = theirs.sum()
        for k, tol in ((1, 0.02), (2, 0.08)):
            if theirs[k] > 0.05 * total:
                assert abs(ours[k] / theirs[k] - 1) < tol, (s, k, ours, theirs)
                checked += 1
        assert abs(ours.sum() / total - 1) < 0.02, (s, ours, theirs)
    assert checked >= 4


def test_outputs_split_by_bounces_sum_to_the_totals():
    """``by_bounce``: (N, K, ...) arrays for the cross-section, profile and images, whose sum
    over K is the result's own; K = ``bounces``; the one-bounce part is what ``bounces=1``
    renders (the images bit for bit; the cross-section to its f32 rounding, as the bins,
    over which the device sums it, reach farther); a profile sums to its cross-section."""
    mesh = mc.dihedral()
    rots = np.stack([mc.dihedral_rotation(10.0), mc.dihedral_rotation(30.0, 10.0)])
    sc = pprender.Scene(mesh, aluminium(0.3))
    one = pprender.render(sc, pprender.Lidar(resolution=32), rots, outputs=("profile", "mueller"))
    assert one.by_bounce is None
    for bounces in (2, 3):
        r = pprender.render(sc, pprender.Lidar(resolution=32, bounces=bounces, path_samples=8), rots,
                            outputs=("profile", "mueller", "range"))
        by = r.by_bounce
        assert by["cross_section"].shape == (2, bounces, 4, 4)
        assert by["profile"].shape == (2, bounces) + r.profile.shape[1:]
        assert by["mueller"].shape == (2, bounces) + r.mueller.shape[1:]
        np.testing.assert_allclose(by["cross_section"][:, 0], one.cross_section, rtol=1e-6,
                                   atol=1e-6 * np.abs(one.cross_section).max())
        np.testing.assert_array_equal(by["mueller"][:, 0], one.mueller)
        np.testing.assert_allclose(by["cross_section"].sum(1), r.cross_section, rtol=1e-12)
        np.testing.assert_allclose(by["profile"].sum(1), r.profile, rtol=1e-12, atol=1e-15)
        # images are f32: within a few roundings of the largest element
        np.testing.assert_allclose(by["mueller"].sum(1), r.mueller, rtol=0, atol=1e-6 * np.abs(r.mueller).max())
        np.testing.assert_allclose(r.profile.sum(1), r.cross_section, rtol=1e-9)
        assert np.all(by["cross_section"][:, 1, 0, 0] > 0.1 * r.cross_section[:, 0, 0])
        # the profile's bins reach the longest path (b ext behind the origin)
        assert r.bin_edges[-1] >= bounces * r.extent


def test_paths_are_the_same_bits_in_batches_on_every_backend_and_change_with_the_seed():
    """The paths' random numbers depend on the seed and pixel only: a batch equals single
    calls bit for bit, the paths (bounces 2 and 3) are the same on the device and the f64
    twin (they are traced on the CPU for every backend), and another seed gives other
    numbers within the noise."""
    mesh = mc.dihedral()
    rots = np.stack([mc.dihedral_rotation(t) for t in (5.0, 25.0, 35.0)])
    sc = pprender.Scene(mesh, aluminium(0.2))
    lidar = pprender.Lidar(resolution=24, bounces=3, path_samples=4, polarization=[1, 1, 0, 0])
    batch = pprender.render(sc, lidar, rots, outputs=("profile", "stokes"))
    for i in range(3):
        one = pprender.render(sc, lidar, rots[i:i + 1], outputs=("profile", "stokes"))
        for key in ("cross_section", "profile", "stokes"):
            np.testing.assert_array_equal(one.by_bounce[key][0], batch.by_bounce[key][i])
    twin = pprender.render(sc, pprender.Lidar(resolution=24, bounces=3, path_samples=4, polarization=[1, 1, 0, 0],
                                              arithmetic="f64"), rots, outputs=("profile", "stokes"))
    for key in ("cross_section", "profile", "stokes"):
        np.testing.assert_array_equal(twin.by_bounce[key][:, 1:], batch.by_bounce[key][:, 1:])
    other = pprender.render(sc, pprender.Lidar(resolution=24, bounces=3, path_samples=4, path_seed=9,
                                               polarization=[1, 1, 0, 0]), rots, outputs=("profile",))
    b2, o2 = batch.by_bounce["cross_section"][:, 1, 0], other.by_bounce["cross_section"][:, 1, 0]
    assert np.all(b2 != o2) and np.allclose(b2, o2, rtol=0.1)


def test_convex_meshes_trace_no_paths():
    """A closed convex mesh has no inter-reflections: bounces 2 and 3 add exactly zero."""
    sc = pprender.Scene(models.sphere(0.5, subdivisions=2), aluminium(0.3))
    r = pprender.render(sc, pprender.Lidar(resolution=24, bounces=3), np.eye(3)[None], outputs=("profile",))
    assert np.all(r.by_bounce["cross_section"][:, 1:] == 0)
    assert r.cross_section[0, 0, 0] > 0


def test_progress_counts_both_passes():
    """With bounces > 1 the progress callback sees the backend's pass and the paths' pass,
    out of twice the batch, ending at the total."""
    calls: list[tuple[int, int]] = []
    sc = pprender.Scene(mc.dihedral(), aluminium(0.3))
    rots = np.stack([mc.dihedral_rotation(t) for t in (5.0, 25.0)])
    pprender.render(sc, pprender.Lidar(resolution=16, bounces=2, path_samples=2), rots, outputs=("profile",),
                    progress=lambda done, total: calls.append((done, total)))
    assert calls and all(t == 4 for _, t in calls) and max(d for d, _ in calls) == 4


@pytest.mark.parametrize("kw, name", [
    ({"bounces": 0}, "bounces"), ({"bounces": 4}, "bounces"), ({"bounces": 2.0}, "bounces"),
    ({"bounces": True}, "bounces"), ({"path_samples": 0}, "path_samples"),
    ({"path_samples": 65537}, "path_samples"), ({"path_samples": 1.5}, "path_samples"),
    ({"path_seed": -1}, "path_seed"), ({"path_seed": 2**32}, "path_seed"), ({"path_seed": "0"}, "path_seed"),
])
def test_bad_path_settings_are_refused(kw, name):
    """Bounces outside 1..3, path counts outside 1..65536 and seeds outside [0, 2^32) are a
    pprender.Error naming the parameter, from Lidar and from Settings."""
    with pytest.raises(pprender.Error, match=name):
        pprender.Lidar(**kw)
    with pytest.raises(pprender.Error, match=name):
        pprender.Settings(**kw)


def test_core_refuses_bad_path_settings():
    """The binding checks them too (a RenderRequest built by hand)."""
    base = dict(resolution=8, supersampling=1, samples=1, bistatic_angle=0.0, polarization=None,
                intensity_only=False, sigma_range=0.01, bin_width=0.01, image=False, range=False,
                profile=True, device="twin")
    for kw, name in (({"bounces": 4}, "bounces"), ({"path_samples": 0}, "path_samples")):
        with pytest.raises(pprender.Error, match=name):
            pprender._core.RenderRequest(**base, **kw)


def test_a_database_of_inter_reflections_records_its_settings(tmp_path):
    """A database built with bounces=2 stores the profiles the renderer returns for it
    (the paths' bins are on the same symmetric grid), and records bounces, path_samples and
    path_seed with the sensor: a rebuild with other path settings is a different database."""
    from pprender.inverse import database

    mesh = mc.dihedral()
    q = np.array([[1.0, 0, 0, 0], [0.9, 0.1, 0.3, 0.2]])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lidar = pprender.Lidar(resolution=24, bounces=2, path_samples=4, polarization=[1, 0, 0, 0])
    ds = database.build_database(tmp_path / "d.zarr", {"corner": mesh}, {"al": aluminium(0.3)}, q, lidar,
                                 progress=False)
    direct = pprender.render(pprender.Scene(mesh, aluminium(0.3)), lidar, q, outputs=("profile",))
    prof = np.asarray(ds["profile"].isel(shape=0, material=0))
    padded = database.pad_profile(direct.profile, direct.bin_edges, ds)
    np.testing.assert_allclose(prof, padded, rtol=1e-6, atol=1e-9 * np.abs(padded).max())
    assert np.abs(direct.by_bounce["profile"][:, 1]).sum() > 0.05 * np.abs(direct.profile).sum()
    sensor = json.loads(ds.attrs["sensor"]) if isinstance(ds.attrs["sensor"], str) else ds.attrs["sensor"]
    assert (sensor["bounces"], sensor["path_samples"], sensor["path_seed"]) == (2, 4, 0)
    with pytest.raises(pprender.Error, match="different parameters"):
        database.build_database(tmp_path / "d.zarr", {"corner": mesh}, {"al": aluminium(0.3)}, q,
                                pprender.Lidar(resolution=24, bounces=2, path_samples=8,
                                               polarization=[1, 0, 0, 0]), progress=False)


def test_paths_that_would_not_fit_in_memory_are_refused():
    """Images split by bounces for thousands of large attitudes would exhaust the memory
    (an allocation failure aborts the process): refused up front, naming bounces and the
    memory needed, before anything renders."""
    sc = pprender.Scene(mc.dihedral(), aluminium(0.3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (3000, 1))
    with pytest.raises(pprender.Error, match=r"bounces.*GiB"):
        pprender.render(sc, pprender.Lidar(resolution=4096, bounces=2), q, outputs=("mueller",))


def test_bistatic_reciprocity_per_bounce():
    """Swapping the transmitter and the receiver (the attitude turned by 180 deg about
    their bisector) leaves each bounce order's M00 unchanged (Helmholtz reciprocity of the
    BRDF and of the path geometry): a rough-aluminium dihedral with its edge across the
    bistatic plane, 0.3 rad bistatic, within 4 combined standard deviations over 4 seeds
    (and 1e-3 of the one-bounce part, which samples nothing)."""
    beta = 0.3
    b = np.array([math.sin(beta), 0.0, 1.0 + math.cos(beta)])
    b /= np.linalg.norm(b)
    swap = 2.0 * np.outer(b, b) - np.eye(3)  # 180 deg about the bisector: Z <-> wi
    r1 = mc.dihedral_rotation(15.0, 10.0)
    r1 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ r1  # edge across the bistatic plane
    rots = np.stack([r1, swap @ r1])
    sc = pprender.Scene(mc.dihedral(), aluminium(0.3))
    runs = np.stack([
        pprender.render(sc, pprender.Lidar(resolution=48, bounces=3, path_samples=32, path_seed=s, bistatic_angle=beta,
                                           polarization=[1, 0, 0, 0], arithmetic="f64"), rots,
                        outputs=("profile",)).by_bounce["cross_section"][..., 0]
        for s in range(4)])  # (seed, attitude, order)
    mean, sd = runs.mean(0), runs.std(0, ddof=1) / 2
    assert np.all(mean[:, 1] > 0.05 * mean[:, 0].max()), mean
    assert abs(mean[0, 0] / mean[1, 0] - 1) < 1e-3, mean
    for k in (1, 2):
        assert abs(mean[0, k] - mean[1, k]) < 4 * math.hypot(sd[0, k], sd[1, k]) + 1e-3 * mean[0, k], (k, mean, sd)


@pytest.mark.parametrize("material", [
    pprender.Material("blinn_phong", m=1e7, eta=complex(1.37, 10.2)),
    pprender.Material("blinn_phong", m=0.0, eta=complex(1.37, 10.2)),
    pprender.Material("beckmann", alpha=0.2, eta=complex(1.0001, 0.0)),
    pprender.Material("beckmann", alpha=0.2, eta=complex(1.0, 1000.0)),
    pprender.Material("ggx", alpha=5.0, eta=complex(1.5, 0.0)),
], ids=["mirror m=1e7", "m=0", "n=1.0001", "k=1000", "ggx alpha 5"])
def test_paths_stay_finite_at_numerical_extremes(material):
    """Extreme materials in a dihedral, seen along its axis, along one plate (grazing the
    other) and beyond its opening: every bounce order finite with M00 >= 0, in the
    cross-section, images and profile (a near-mirror corner returns a very large, finite
    cross-section: the lobe of a m = 1e7 surface is 1e-7 sr wide)."""
    sc = pprender.Scene(mc.dihedral(), material)
    for t in (0.0, 44.9, 60.0):
        r = pprender.render(sc, pprender.Lidar(resolution=24, bounces=3, path_samples=8),
                            mc.dihedral_rotation(t)[None], outputs=("profile", "mueller"))
        by = r.by_bounce
        assert np.all(np.isfinite(by["cross_section"])) and np.all(by["cross_section"][..., 0, 0] >= 0)
        assert np.all(np.isfinite(by["mueller"])) and np.all(np.isfinite(by["profile"]))


def test_common_random_numbers_make_the_paths_smooth_in_the_attitude():
    """The paths' random numbers are keyed by the seed and the pixel, not the attitude: a
    fit stepping the attitude by 1e-3 deg sees each bounce order change smoothly (first
    differences under 1e-4 of the value, second differences under 1e-6: no jitter for nlopt
    to chase), while another seed moves them by the paths' noise (over 1e-3 here)."""
    sc = pprender.Scene(mc.dihedral(), aluminium(0.3))
    rots = np.stack([mc.dihedral_rotation(20.0 + d) for d in (0.0, 1e-3, 2e-3)])

    def orders(seed: int) -> np.ndarray:
        lidar = pprender.Lidar(resolution=32, bounces=3, path_samples=8, path_seed=seed, polarization=[1, 0, 0, 0])
        return pprender.render(sc, lidar, rots, outputs=("profile",)).by_bounce["cross_section"][..., 0]

    a, b = orders(0), orders(1)
    for k in (1, 2):
        assert np.all(np.abs(np.diff(a[:, k])) < 1e-4 * a[0, k]), a[:, k]
        assert abs(a[0, k] - 2 * a[1, k] + a[2, k]) < 1e-6 * a[0, k], a[:, k]
        assert abs(a[0, k] - b[0, k]) > 1e-3 * a[0, k], (a[0], b[0])
