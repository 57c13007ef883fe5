"""The one-call GPU check (scripts/gpu_check.py) runs end to end on lavapipe
(``--device cpu``), passes its own agreement limits there and writes its report; its
shell wrappers parse. No test needs a GPU: on one, the same script runs with
``--device gpu`` (docs/gpu-benchmark.md)."""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load():
    spec = importlib.util.spec_from_file_location("gpu_check", ROOT / "scripts" / "gpu_check.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_gpu_check_on_lavapipe(tmp_path) -> None:
    check = _load()
    out = tmp_path / "gpu.md"
    assert check.main(["--device", "cpu", "--budget", "1", "--quick", "--write", str(out)]) == 0
    text = out.read_text()
    assert "llvmpipe" in text
    assert text.count("| pass |") == 4 and "FAIL" not in text
    assert "Roll invariance" in text and "(limit 0.0001): pass." in text
    assert "realizations/s" in text
    assert "## Where the time goes: Mueller outputs, batch 4" in text
    assert "| profile + mueller + range |" in text
    assert "## What the device time scales with: profile only (Stokes, H), batch 4" in text
    assert "| icosphere, 20480 triangles, 128x128 |" in text


def test_gpu_check_grades_a_wrong_kernel() -> None:
    """The per-pixel grading fails a kernel 1% off everywhere, and one with many outliers,
    and passes isolated rasterizer ties."""
    import numpy as np

    check = _load()
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.5, 1.0, size=(2, 16, 16, 4, 4))
    assert np.percentile(check._pixel_errors(1.01 * ref, ref), 99) > check.LIMITS["image_p99"]
    tie = ref.copy()
    tie[0, 3, 4] *= 1.5  # one pixel of 512 sees another surface
    px = check._pixel_errors(tie, ref)
    assert np.percentile(px, 99) <= check.LIMITS["image_p99"]
    assert np.mean(px > check.OUTLIER) == pytest.approx(1 / 512)
    tie[1, :2] *= 1.5  # 32 pixels of 512: a broken kernel, not ties
    assert np.mean(check._pixel_errors(tie, ref) > check.OUTLIER) > check.LIMITS["outliers"]


@pytest.mark.parametrize("script", ["gpu_check.sh", "gpu_bundle.sh"])
def test_gpu_scripts_parse(script) -> None:
    r = subprocess.run(["bash", "-n", str(ROOT / "scripts" / script)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
