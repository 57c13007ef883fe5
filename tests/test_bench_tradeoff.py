"""A small run of the speed/accuracy benchmark (python -m pprender.bench_tradeoff)."""

from __future__ import annotations

import math

from pprender import bench_tradeoff


def test_quick_tradeoff_is_ordered_and_finite():
    rows = bench_tradeoff.measure(quick=True, batch=4, repeats=1, progress=False)
    by = {r.setting: r for r in rows}
    assert set(by) == {"reference", "fast", "balanced", "accurate"}
    for r in rows:
        assert all(math.isfinite(v) for v in (r.seconds, r.img_max, r.img_rms00, r.prof_l1, r.total_rel))
    # each setting halves the pixel and refines the tables: errors against the f64
    # reference (at 8x the fast resolution) must fall from fast to balanced to accurate
    assert by["fast"].img_rms00 > by["balanced"].img_rms00 > by["accurate"].img_rms00
    assert by["fast"].prof_l1 > by["balanced"].prof_l1 > by["accurate"].prof_l1
    # and the smooth sphere's total is within 2e-3 even at the fast setting
    assert by["fast"].total_rel < 2e-3
    assert "| fast |" in bench_tradeoff.summary(rows)
