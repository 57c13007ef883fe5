"""Coherent backscatter of ``orders="surface"`` against the explicit microsurface's coherent
tally (issue 24, item 3): a small version of ``scripts/coherent_backscatter_reference.py``
(docs/coherent-backscatter.md). The path bank is the one ``tests/test_path_bank.py``'s
sphere test uses (alpha 0.8, 2e5 rays, in the session's temporary cache)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import pprender

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import coherent_backscatter_reference as cbr  # noqa: E402

AL = 1.3763 + 10.2449j


def _model(theta: float, cbe: bool, terms: tuple[str, ...]) -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.8, eta=AL, terms=terms, orders="surface", bank_rays=200_000,
                             coherent_backscatter=cbe, wavelength=1e-6,
                             correlation_length=cbr.CORR_LENGTH * 1e-6)


@pytest.mark.parametrize("theta", [0.0, 30.0])
def test_order_two_peak_width_matches_the_surface(theta: float, tmp_path: Path) -> None:
    """Order 2 enhances 2x at exact backscatter in every element, and its peak's half width
    (M00 against the bistatic angle) is within the issue's 20% of the reference's coherent
    tally (8e6 rays on 16 surfaces of their own seeds; standard errors 3-10% at the
    crossing), in the plane of incidence (the mean of the two sides: the model's width on
    either side comes from the bank's incidence nodes on that side, each noisy with this
    small bank) and across it. At 30 deg the peak is narrower across the plane than in it
    (the separations' height component enters only in the plane, where it shortens their
    projection transverse to wi). Measured: 0 deg, reference (in, out) 0.0228, 0.0221 rad,
    model 0.0223, 0.0223; 30 deg, reference 0.0263, 0.0170, model 0.0276, 0.0154 (the
    docs page, with the default banks, has 0.0272 / 0.0273 in and 0.0164 / 0.0167 across
    at alpha 0.8)."""
    wi, bist = cbr.directions(theta)
    ref = cbr.trace(0.8, theta, "aluminium", 8_000_000, tmp_path)
    on, off = _model(theta, True, ("double",)), _model(theta, False, ("double",))
    wis = np.repeat(wi[None], len(bist), 0)
    coh = pprender.brdf(on, wis, bist) - pprender.brdf(off, wis, bist)
    inc = pprender.brdf(off, wi, wi)
    np.testing.assert_allclose(coh[0], inc, rtol=1e-12, atol=1e-15)
    nb = len(cbr.BETAS)
    w = {}
    for j, (az, _) in enumerate(cbr.AZIMUTHS):
        sl = slice(j * nb, (j + 1) * nb)
        w_ref, _ = cbr.half_width(ref["coherent"][0][sl][:, 0, 0])
        w_mod, _ = cbr.half_width(coh[sl][:, 0, 0])
        w[az] = (w_ref, w_mod)
    pairs = {"in": tuple(0.5 * (w["in+"][k] + w["in-"][k]) for k in range(2)), "out": w["out"]}
    for name, (w_ref, w_mod) in pairs.items():
        assert abs(w_mod / w_ref - 1) < cbr.TOL_W, (name, pairs, w)
