"""The one-call GPU check (scripts/gpu_check.py) runs end to end on lavapipe
(``--device cpu``), passes its own limits there (the agreement of standard scenes, the
illuminated area, surface orders) and writes its report; its gradings fail wrong
results; its shell wrappers parse. No test needs a GPU: on one, the same script runs with
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
    import pprender

    check = _load()
    out = tmp_path / "gpu.md"
    cache = pprender.cache_dir()
    assert check.main(["--device", "cpu", "--budget", "1", "--quick", "--write", str(out)]) == 0
    assert pprender.cache_dir() == cache  # the surface-orders check turns the disk cache off, then back
    text = out.read_text()
    assert "llvmpipe" in text
    # 4 agreement rows, 1 illuminated-area row, 2 surface-orders rows
    assert text.count("| pass |") == 7 and "FAIL" not in text
    assert "Roll invariance" in text and "(limit 0.0001): pass." in text
    assert "## Illuminated area: f32 device kernel against the f64 CPU twin" in text
    assert "## Surface orders (calibrated single term): f32 device kernel against the f64 CPU twin" in text
    assert "| `shader` |" in text and "| `table` |" in text
    assert "- surface-orders material: 20,000-ray path bank, calibration, tables (s): " in text
    assert "realizations/s" in text
    assert "## Where the time goes: Mueller outputs, batch 4" in text
    assert "| profile + mueller + range |" in text
    assert "## What the device time scales with: profile only (Stokes, H), batch 4" in text
    assert "| icosphere, 20480 triangles, 128x128 |" in text
    assert "## Ray casting: the renderer's tree walked in the kernel and on the CPU" in text
    # primary and secondary rays, f64 and the kernel on lavapipe (+ Embree, installed here),
    # the kernel agreeing with the f64 tree on every one of the 2,000 rays' hits
    for kind in ("primary", "secondary"):
        row = next(line for line in text.splitlines()
                   if line.startswith(f"| CubeSat 3U | 11,840 | {kind} |") and "kernel (llvmpipe" in line)
        assert row.split("|")[9:11] == [" 0 ", " 0 "], row
    assert "x the f64 tree's rate over the 2 rows." in text


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


def test_gpu_check_grades_a_wrong_illuminated_area() -> None:
    """The illuminated-area grading fails an area 5% off everywhere, or 5% off in two
    bins where the profile agrees, or a profile 5% off (which would excuse the area);
    it passes a rasterizer tie (a bin's area and S0 profile moved together) and ignores
    bins below 1% of the peak."""
    import numpy as np

    check = _load()
    rng = np.random.default_rng(2)
    s0 = rng.uniform(0.1, 1.0, size=(2, 40))
    s0[:, :3] = 1e-4  # faint bins, below 1% of the peak
    profile = s0[..., None, None] * np.eye(4)
    area = rng.uniform(0.01, 0.05, size=(2, 40))

    def grade(a: np.ndarray, p: np.ndarray = profile) -> dict:
        return check.area_errors(a, area, p, profile)

    e = grade(area.copy())
    assert e["pass"] and e["median"] == 0 and e["bins"] == 2 * 37
    assert not grade(1.05 * area)["pass"]
    two = area.copy()
    two[0, 18:20] *= 1.05
    e = grade(two)
    assert e["median"] == 0 and not e["pass"] and e["worst"] == pytest.approx(0.05)
    assert not grade(area, 1.05 * profile)["pass"]
    tie, ptie = area.copy(), profile.copy()
    tie[1, 25] *= 1.10  # a tie: the area moves 2x what the S0 profile does
    ptie[1, 25] *= 1.05
    tie[0, 1] *= 1.5  # a faint bin
    e = grade(tie, ptie)
    assert e["pass"] and e["max"] == pytest.approx(0.10) and e["max_profile"] == pytest.approx(0.05)


def test_gpu_check_grades_a_wrong_surface_orders_kernel() -> None:
    """The surface-orders grading fails Mueller images 0.5% off everywhere and ones
    scaled by 0.2-5% from pixel to pixel (what an uncalibrated single term does), and
    passes one rasterizer tie."""
    import numpy as np

    check = _load()
    rng = np.random.default_rng(3)
    ref = rng.uniform(-0.2, 0.2, size=(1, 48, 48, 4, 4))
    ref[..., 0, 0] = rng.uniform(0.5, 1.0, size=(1, 48, 48))
    tot = ref.sum(axis=(1, 2))

    def grade(a: np.ndarray) -> dict:
        return check.surface_errors(a, ref, a.sum(axis=(1, 2)), tot)

    e = grade(ref.copy())
    assert e["pass"] and e["image_p99"] == 0 and e["total"] == 0
    e = grade(1.005 * ref)
    assert not e["pass"] and e["image_p99"] > check.LIMITS["surface_p99"]
    assert e["total"] > check.LIMITS["surface_total"]
    scale = rng.uniform(1.002, 1.05, size=(1, 48, 48, 1, 1))
    assert not grade(scale * ref)["pass"]
    tie = ref.copy()
    tie[0, 10, 11] *= 1.5  # one pixel of 2304 sees another facet
    e = grade(tie)
    assert e["pass"] and e["max"] == pytest.approx(0.5) and e["outliers"] == pytest.approx(1 / 2304)


@pytest.mark.parametrize("script", ["gpu_check.sh", "gpu_bundle.sh"])
def test_gpu_scripts_parse(script) -> None:
    r = subprocess.run(["bash", "-n", str(ROOT / "scripts" / script)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
