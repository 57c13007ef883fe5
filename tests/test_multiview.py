"""Multiview visibility passes: a device with wgpu's MULTIVIEW feature rasterizes up to 31
layers (attitudes or visibility samples) per pass (``device_info()["raster_views"]``;
lavapipe has 6). Every attitude is drawn with the same arithmetic into its own layer, so
the results equal one pass per layer (``PPRENDER_RASTER_VIEWS=1``) bit for bit, partial
groups at the end of a chunk and the bistatic transmitter's passes included."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import pprender
from pprender import models

CASES = [dict(resolution=24), dict(resolution=20, pixel_samples=2), dict(resolution=20, bistatic_angle=0.3),
         dict(resolution=16, pixel_samples=8)]

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import pprender
    from pprender import models

    CASES = {cases!r}
    scene = pprender.Scene(models.cubesat("3U"), "aluminium")
    q = np.random.default_rng(7).normal(size=(7, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = {{"views": np.array(pprender.device_info("cpu")["raster_views"])}}
    for i, kw in enumerate(CASES if len(sys.argv) < 3 else []):
        r = pprender.render(scene, pprender.Lidar(**kw), q, outputs=("profile", "mueller", "range"), device="cpu")
        out[f"profile{{i}}"], out[f"mueller{{i}}"], out[f"range{{i}}"] = r.profile, r.mueller, r.range
    np.savez(sys.argv[1], **out)
""")


def _render_in_subprocess(tmp_path, views: str | None, render: bool = True) -> dict[str, np.ndarray]:
    env = dict(os.environ)
    env.pop("PPRENDER_RASTER_VIEWS", None)
    if views is not None:
        env["PPRENDER_RASTER_VIEWS"] = views
    out = tmp_path / f"views-{views}.npz"
    script = tmp_path / "render.py"
    script.write_text(SCRIPT.format(cases=CASES))
    args = [sys.executable, str(script), str(out)] + ([] if render else ["views only"])
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return dict(np.load(out))


def test_multiview_equals_one_layer_per_pass(tmp_path) -> None:
    one = _render_in_subprocess(tmp_path, "1")
    default = _render_in_subprocess(tmp_path, None)
    assert int(one["views"]) == 1
    assert int(default["views"]) == pprender.device_info("cpu")["raster_views"] >= 1
    for i in range(len(CASES)):
        for k in ("profile", "mueller", "range"):
            np.testing.assert_array_equal(default[f"{k}{i}"], one[f"{k}{i}"], err_msg=f"{k} of {CASES[i]}")


@pytest.mark.parametrize("value", ["0", "-3", "many"])
def test_a_meaningless_views_setting_is_ignored(tmp_path, value) -> None:
    """Only a positive integer caps the views; anything else leaves the device's count."""
    r = _render_in_subprocess(tmp_path, value, render=False)
    assert int(r["views"]) == pprender.device_info("cpu")["raster_views"]


def test_the_views_benchmark_runs_and_finds_the_outputs_equal(capsys) -> None:
    """benchmarks/bench_raster_views.py at a tiny size, single-term aluminium (its double
    term's tables take seconds in each fresh process): both view counts, equal outputs."""
    import bench_raster_views

    assert bench_raster_views.main(["--device", "cpu", "--rounds", "1", "--batches", "2", "--resolution", "24",
                                    "--terms", "single"]) == 0
    out = capsys.readouterr().out
    assert "outputs identical across view counts: yes" in out
    assert "| 1 | profile only (Stokes, H) | 2 |" in out
