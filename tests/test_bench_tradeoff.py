"""A small run of the speed/accuracy benchmark (python benchmarks/bench_tradeoff.py)."""

from __future__ import annotations

import math
from pathlib import Path

import bench_tradeoff


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


def test_quick_knobs_each_change_what_they_should():
    rows = bench_tradeoff.measure_knobs(quick=True, batch=2, repeats=1, progress=False)
    by = {(r.group, r.value): r for r in rows}
    for r in rows:
        assert all(math.isfinite(v) for v in (r.seconds, r.setup_seconds, r.img_rms00, r.pixel_rel, r.prof_l1,
                                                r.total_rel)), r
    # more visibility samples per pixel: a smaller image error against the reference at 8x
    assert by[("sampling", "16")].img_rms00 < by[("sampling", "1")].img_rms00
    # BRDF group, same pixels as its reference: the reference row is its own truth, the
    # fine grid beats the coarse one per pixel, and f64 arithmetic on the default grid
    # leaves the tables' error alone (1e-4 of M00, docs/render-table.md)
    ref = by[("BRDF", "reference (exact f64 core)")]
    assert ref.img_rms00 == 0 and ref.pixel_rel == 0
    assert by[("BRDF", "fast's grid")].pixel_rel > by[("BRDF", "accurate's grid")].pixel_rel
    assert 0 < by[("BRDF", "f64 (default grid)")].pixel_rel < 1e-4
    assert "## One knob at a time" in bench_tradeoff.knobs_text(rows)


def test_write_targets_the_repositorys_docs():
    """``--write`` writes into the repository's docs/ (it pointed one level above the
    repository after the benchmarks moved out of the package, and failed after the whole
    run): the pages it writes exist there."""
    import bench_equal_error

    root = Path(__file__).resolve().parents[1]
    for mod, page in ((bench_tradeoff, "tradeoff.md"), (bench_equal_error, "equal-error.md")):
        assert mod.DOCS == root / "docs"
        assert (mod.DOCS / page).is_file()
