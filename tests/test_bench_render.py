"""The render benchmark's measurements (python benchmarks/bench_render.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from bench_render import _peak_rss_mb


def test_a_fresh_process_reports_its_own_peak_memory() -> None:
    """The memory rows spawn a fresh process per batch size; its peak must be its own.
    ``getrusage(RUSAGE_SELF).ru_maxrss`` is not: Linux carries the parent's peak into a
    child spawned by (v)fork + exec, and the rows read the benchmark's own 541 to 721 MB
    where the child peaks near 250. With 400 MB held here, a child that only imports
    numpy must report well under that."""
    held = np.ones(400 * 2**20 // 8)
    held[::512] = 2.0  # touch every page
    here = _peak_rss_mb()
    assert here > 400, here
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    r = subprocess.run(
        [sys.executable, "-c", "import numpy; from bench_render import _peak_rss_mb; print(_peak_rss_mb())"],
        capture_output=True, text=True, check=True, env=env,
    )
    child = float(r.stdout.strip().splitlines()[-1])
    print(f"parent {here:.0f} MB, child {child:.0f} MB")
    assert 0 < child < 300, child
    assert float(held.sum()) > 0
