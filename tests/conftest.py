"""Shared pytest fixtures.

* ``rng``: a seeded NumPy generator (``np.random.default_rng(12345)``), fresh per test, so
  every test that draws random geometry is reproducible on its own.
* Hypothesis runs derandomized by default (profile ``"repeatable"``: the same examples on
  every run and machine, so CI cannot fail on a case no earlier run saw);
  ``HYPOTHESIS_PROFILE=explore`` draws fresh random examples (the library's default) for a
  search. A case found that way is added to its test with ``@example``.
* ``mitsuba``: the ``mitsuba`` module with the ``llvm_ad_mono_polarized`` variant set
  (vectorized, float32, polarized). Importing Mitsuba is deferred to the first test that
  asks for it. If Mitsuba cannot be imported or the variant is missing, every test using
  the fixture fails (never skips) with the reason.
* The path banks of ``orders="surface"`` are cached on disk in a fresh temporary directory
  for the whole session (``PPRENDER_CACHE_DIR``, set here before anything imports
  pprender, and inherited by the tests' subprocesses; removed at exit): a warm cache in
  the user's ``~/.cache/pprender`` must never hide the cold cost of a bank, and the tests
  must not fill it. Under pytest-xdist (``make test`` runs a worker per core) the workers share
  the controller's directory, so a bank one worker traced is read by the others (writes
  are atomic renames, ``src/brdf/bank/cache.rs``).
* The path banks' default rays are 2e5 (``PPRENDER_BANK_RAYS``, set here likewise), not the
  library's 4e6: ``pprender.materials`` gives its Beckmann materials ``orders="surface"``,
  so most test files build banks, and at 4e6 rays each node costs 30 s to minutes on 2
  cores. Tests that measure the banks' accuracy pass ``bank_rays`` themselves; the full
  count's cost and noise are measured by benchmarks/bench_surface_orders.py and
  scripts/bank_alpha_interpolation.py.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get("PPRENDER_TEST_CACHE_DIR"):
    # a pytest-xdist worker: the session's directory, made (and removed) by the controller
    _CACHE_DIR = os.environ["PPRENDER_TEST_CACHE_DIR"]
else:
    _CACHE_DIR = tempfile.mkdtemp(prefix="pprender-test-cache-")
    os.environ["PPRENDER_TEST_CACHE_DIR"] = _CACHE_DIR
    atexit.register(shutil.rmtree, _CACHE_DIR, ignore_errors=True)
os.environ["PPRENDER_CACHE_DIR"] = _CACHE_DIR
os.environ["PPRENDER_BANK_RAYS"] = "200000"

import glob  # noqa: E402
import importlib.metadata  # noqa: E402
import sys  # noqa: E402
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("repeatable", derandomize=True, database=None)
settings.register_profile("explore")
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

MITSUBA_VARIANT = "llvm_ad_mono_polarized"

# The benchmarks live outside the package (benchmarks/, run as scripts); tests of their
# measurements import them from there.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.fixture
def rng() -> np.random.Generator:
    """Seeded random generator, the same stream in every test that uses it."""
    return np.random.default_rng(12345)


def _version_tuple(version: str) -> tuple[int, ...]:
    out = []
    for part in version.split(".")[:3]:
        digits = "".join(ch for ch in part if ch.isdigit())
        out.append(int(digits) if digits else 0)
    return tuple(out)


def _prepare_llvm() -> None:
    """drjit >= 1.5 aborts the whole process (uncatchable) on the first kernel with
    LLVM 15/16, so point it at a newer libLLVM before importing it, or fail cleanly.
    drjit 1.4.0 (pinned with mitsuba 3.9.0) works with Debian 12's LLVM 15."""
    try:
        version = importlib.metadata.version("drjit")
    except importlib.metadata.PackageNotFoundError:
        pytest.fail("drjit is not installed: `pip install mitsuba==3.9.0 drjit==1.4.0` (make setup)", pytrace=False)
    if _version_tuple(version) < (1, 5) or os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    candidates = sorted(
        glob.glob("/usr/lib/llvm-1[7-9]/lib/libLLVM*.so*")
        + glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM*1[7-9]*.so*")
        + glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM.so.1[7-9]*")
    )
    if not candidates:
        pytest.fail(
            f"drjit {version} needs LLVM >= 17 (it aborts the process with LLVM 15/16); install "
            "libllvm19 or pin mitsuba==3.9.0 / drjit==1.4.0",
            pytrace=False,
        )
    os.environ["DRJIT_LIBLLVM_PATH"] = candidates[-1]


@pytest.fixture(scope="session")
def _mitsuba_module() -> ModuleType:
    _prepare_llvm()
    try:
        import drjit  # noqa: F401
        import mitsuba
    except Exception as e:  # ImportError, or a missing shared library
        pytest.fail(f"cannot import mitsuba/drjit: {e!r}", pytrace=False)
    if MITSUBA_VARIANT not in mitsuba.variants():
        pytest.fail(f"mitsuba has no {MITSUBA_VARIANT} variant (has {mitsuba.variants()})", pytrace=False)
    mitsuba.set_variant(MITSUBA_VARIANT)
    return mitsuba


@pytest.fixture
def mitsuba(_mitsuba_module: ModuleType) -> ModuleType:
    """``mitsuba`` with ``llvm_ad_mono_polarized`` selected (re-selected for each test in
    case another test switched the variant)."""
    _mitsuba_module.set_variant(MITSUBA_VARIANT)
    return _mitsuba_module
