"""Bad input raises pprender.Error (a ValueError) whose message names the parameter."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender

NAN, INF = math.nan, math.inf


def test_error_is_value_error() -> None:
    assert issubclass(pprender.Error, ValueError)
    assert pprender.Error.__module__ == "pprender"


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(m=NAN), "m"),
        (dict(m=-1.0), "m"),
        (dict(m=INF), "m"),
        (dict(m=1e11), "m"),
        (dict(distribution="beckmann", alpha=NAN), "alpha"),
        (dict(distribution="beckmann", alpha=0.0), "alpha"),
        (dict(distribution="ggx", alpha=-0.1), "alpha"),
        (dict(distribution="ggx", alpha=INF), "alpha"),
        (dict(distribution="ggx", m=1.0, alpha=0.1), "m"),
        (dict(distribution="ggx"), "m"),
        (dict(distribution="phong", m=1.0), "distribution"),
        (dict(m=1.0, eta=complex(NAN, 0)), "eta"),
        (dict(m=1.0, eta=complex(1.5, NAN)), "eta"),
        (dict(m=1.0, eta=0.0), "eta"),
        (dict(m=1.0, eta=-1.5), "eta"),
        (dict(m=1.0, eta=complex(1.5, -0.1)), "eta"),
        (dict(m=1.0, eta=complex(1.5, INF)), "eta"),
        (dict(m=1.0, shadowing="walter"), "shadowing"),
        (dict(m=1.0, correlation="cos"), "correlation"),
        (dict(m=1.0, smith_g1="approx"), "smith_g1"),
        (dict(m=1.0, masking="fast"), "masking"),
        (dict(m=1.0, terms=("single", "triple")), "terms"),
        (dict(m=1.0, terms=("double",), double_order=2), "double_order"),
        (dict(m=1.0, terms=("double",), wavelength=-1e-6), "wavelength"),
        (dict(m=1.0, terms=("double",), correlation_length=NAN), "correlation_length"),
        (dict(m=1.0, terms=("double",), double_masking="exact"), "double_masking"),
        (dict(m=1.0, terms=("double",), shadowing="none"), "shadowing"),
        (dict(m=1.0, terms=()), "terms"),
        (dict(m=1.0, shadowing="none"), "shadowing"),
        (dict(m=1.0, diffuse_albedo=1.5, terms=("single", "diffuse")), "diffuse_albedo"),
        (dict(m=1.0, diffuse_albedo=NAN), "diffuse_albedo"),
        (dict(m=1.0, terms=("single", "diffuse")), "diffuse_albedo"),
        (dict(distribution="beckmann", alpha=0.2, masking="seed"), "masking"),
        # Wrong types (issue 21): a raw TypeError from PyO3 named nothing.
        (dict(distribution="beckmann", alpha="0.2"), "alpha"),
        (dict(m="10"), "m"),
        (dict(m=1.0, eta="1.5+2j"), "eta"),
        (dict(m=1.0, eta=None), "eta"),
        (dict(m=1.0, terms="single"), "terms"),
        (dict(m=1.0, terms=None), "terms"),
        (dict(m=1.0, terms=(1, 2)), "terms"),
        (dict(m=1.0, diffuse_albedo="0.5"), "diffuse_albedo"),
        (dict(m=1.0, double_order=48.5), "double_order"),
        (dict(m=1.0, wavelength="1064e-9"), "wavelength"),
        (dict(m=1.0, correlation_length=None), "correlation_length"),
        (dict(m=1.0, shadowing=None), "shadowing"),
        (dict(m=1.0, name=3), "name"),
        (dict(m=1.0, coherent_backscatter="yes"), "coherent_backscatter"),
        (dict(distribution=None, m=1.0), "distribution"),
    ],
)
def test_bad_material(kwargs: dict, name: str) -> None:
    dist = kwargs.pop("distribution", "blinn_phong")
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        pprender.Material(dist, **kwargs)


@pytest.fixture(scope="module")
def mat() -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.5)


@pytest.mark.parametrize(
    "wi, wo, name, what",
    [
        ([0, 0, NAN], [0, 0, 1.0], "wi", "finite"),
        ([0, 0, 1.0], [INF, 0, 1.0], "wo", "finite"),
        ([0.6, 0, -0.8], [0, 0, 1.0], "wi", "below the horizon"),
        ([0, 0, 1.0], [0, 0.6, -0.8], "wo", "below the horizon"),
        ([0, 0, 2.0], [0, 0, 1.0], "wi", "unit"),
        ([0, 0, 0.0], [0, 0, 1.0], "wi", "unit"),
        ([[0, 0, 1.0]] * 2, [[0, 0, 1.0]] * 3, "wi", "broadcast"),
        ([0, 0, 1.0, 0], [0, 0, 1.0], "wi", r"\(\.\.\., 3\)"),
        ("up", [0, 0, 1.0], "wi", "float64"),
    ],
)
def test_bad_directions(mat: pprender.Material, wi: object, wo: object, name: str, what: str) -> None:
    with pytest.raises(pprender.Error, match=rf"{name}.*{what}|{what}.*{name}"):
        pprender.brdf(mat, wi, wo)


def test_bad_frame(mat: pprender.Material) -> None:
    with pytest.raises(pprender.Error, match="frame"):
        pprender.brdf(mat, [0, 0, 1.0], [0, 0, 1.0], frame="lab")


def test_bad_albedo_args(mat: pprender.Material) -> None:
    with pytest.raises(pprender.Error, match="order"):
        pprender.albedo(mat, [0, 0, 1.0], order=2)
    with pytest.raises(pprender.Error, match="wi"):
        pprender.albedo(mat, [0, 0.6, -0.8])


def test_extreme_but_valid_inputs_are_finite() -> None:
    # m from 0 to 1e7, eta near 1 and huge, grazing to 1e-7 rad: finite, non-negative.
    g = np.random.default_rng(11)
    for m in [0.0, 1e-6, 1.0, 5000.0, 1e6, 1e7]:
        for eta in [1 + 1e-6, 1.5, 0.2 + 3.4j, 1e3 + 1e3j]:
            mat = pprender.Material("blinn_phong", m=m, eta=eta)
            t = np.concatenate([[0.0, np.pi / 2 - 1e-7], g.uniform(0, np.pi / 2, 6)])
            wi = np.stack([np.sin(t), 0 * t, np.cos(t)], -1)
            wo = np.stack([np.sin(t[::-1]) * np.cos(1.0), np.sin(t[::-1]) * np.sin(1.0), np.cos(t[::-1])], -1)
            for a, b in [(wi, wo), (wi, wi)]:
                M = pprender.brdf(mat, a, b)
                assert np.all(np.isfinite(M)), (m, eta)
                assert np.all(M[:, 0, 0] >= 0)
            alb = pprender.albedo(mat, wi, order=64)
            assert np.all(np.isfinite(alb)) and np.all(alb <= 1 + 1e-4), (m, eta, alb)
