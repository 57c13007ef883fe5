"""The hand-written stubs of the extension match what it exports (mypy.stubtest), and
the package type-checks against them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_stubtest_core() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "pprender._core", "--ignore-missing-stub"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_package() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "mypy", "--ignore-missing-imports", "-p", "pprender"],
        capture_output=True,
        text=True,
        cwd=ROOT / "python",
    )
    assert r.returncode == 0, r.stdout + r.stderr
