"""The path banks' disk cache (issue 24, "Bad input"): a bank traced by one process is read
by the next (the same BRDF, the entry untouched); a corrupt or truncated entry is traced
again and replaced, never trusted; ``prune_cache`` removes the entries this version cannot
read; ``set_cache_dir`` refuses what is not a directory, naming ``cache_dir``. Small banks (``bank_rays`` of a few ten thousand: seconds), in a
temporary directory of the test's own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pprender

# rays of a bank no other test builds, so that this process traces it (the banks in memory
# are keyed on alpha node and rays)
RAYS = 20_011
ALPHA = 0.5
ETA = complex(1.3, 2.1)

# builds the material in a new process and prints its BRDF at a few pairs
SCRIPT = f"""
import json, sys
import numpy as np
import pprender
m = pprender.Material("beckmann", alpha={ALPHA}, eta=complex({ETA.real}, {ETA.imag}),
                      terms=("single", "double", "multiple"), orders="surface",
                      bank_rays={RAYS})
wi = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 0.866], [0.3, 0.4, 0.866]])
wo = np.array([[0.0, 0.0, 1.0], [-0.2, 0.3, 0.93], [0.6, -0.1, 0.79]])
wi /= np.linalg.norm(wi, axis=1, keepdims=True)
wo /= np.linalg.norm(wo, axis=1, keepdims=True)
json.dump(pprender.brdf(m, wi, wo).tolist(), sys.stdout)
"""


def _in_new_process(cache: Path) -> tuple[np.ndarray, str]:
    env = dict(os.environ, PPRENDER_CACHE_DIR=str(cache), PPRENDER_PROGRESS="0")
    r = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    return np.array(json.loads(r.stdout)), r.stderr


@pytest.fixture
def cache(tmp_path: Path):
    old = pprender.cache_dir()
    pprender.set_cache_dir(tmp_path)
    yield tmp_path
    pprender.set_cache_dir(old)


def _entry(cache: Path) -> Path:
    entries = sorted(cache.glob("bank-alpha0.5000-*.ppbank"))
    assert len(entries) == 1, list(cache.iterdir())
    return entries[0]


def test_a_bank_is_traced_once_and_read_by_the_next_process(cache: Path) -> None:
    assert pprender.cache_dir() == cache
    values, _ = _in_new_process(cache)  # traces and writes the entry
    entry = _entry(cache)
    good = entry.read_bytes()
    stat = entry.stat()
    # the same material in this process (its own memory cache is cold for these rays): read
    m = pprender.Material("beckmann", alpha=ALPHA, eta=ETA, terms=("single", "double", "multiple"),
                          orders="surface", bank_rays=RAYS)
    assert m.orders == "surface"
    again, _ = _in_new_process(cache)
    np.testing.assert_array_equal(again, values)
    after = entry.stat()
    assert (after.st_ino, after.st_mtime_ns) == (stat.st_ino, stat.st_mtime_ns), "the entry was rewritten"
    assert [p.name for p in cache.iterdir()] == [entry.name], "a temporary file was left"

    # corrupt (one byte in the middle) or truncated: traced again, the same values, and the
    # entry replaced by a valid one (tracing is deterministic: the same bytes)
    flipped = bytearray(good)
    flipped[len(good) // 2] ^= 0x40
    for bad in (bytes(flipped), good[: len(good) // 3]):
        entry.write_bytes(bad)
        rebuilt, err = _in_new_process(cache)
        assert "not valid" in err and "tracing it again" in err, err
        np.testing.assert_array_equal(rebuilt, values)
        assert entry.read_bytes() == good


def test_prune_cache_removes_what_this_version_cannot_read(tmp_path: Path) -> None:
    """``prune_cache``: an entry another version wrote (the same file with another version
    string in its header) and a file with a damaged header are removed, this version's
    entry and files that are not entries are kept, and the kept entry is still read (not
    traced again); ``all=True`` removes it too; bad arguments name the parameter."""
    values, _ = _in_new_process(tmp_path)  # writes this version's entry
    entry = _entry(tmp_path)
    good = entry.read_bytes()
    vlen = int.from_bytes(good[12:16], "little")
    version = good[16 : 16 + vlen].decode()
    old = version.replace(pprender.__version__, "0.0.9", 1).encode()
    assert len(old) != 0 and old != version.encode()
    foreign = tmp_path / "bank-alpha0.5000-00000000000000aa.ppbank"
    foreign.write_bytes(good[:12] + len(old).to_bytes(4, "little") + old + good[16 + vlen :])
    damaged = tmp_path / "bank-alpha0.5000-00000000000000bb.ppbank"
    damaged.write_bytes(good[:20])
    mine = tmp_path / "notes.txt"
    mine.write_text("not a bank")
    gone = foreign.stat().st_size + damaged.stat().st_size
    # a process about to trace a bank says what it can never read, and how to remove it
    env = dict(os.environ, PPRENDER_CACHE_DIR=str(tmp_path), PPRENDER_PROGRESS="0")
    other = SCRIPT.replace(f"bank_rays={RAYS}", f"bank_rays={RAYS + 2}")
    r = subprocess.run([sys.executable, "-c", other], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0 and "2 path-bank entries" in r.stderr and "prune_cache()" in r.stderr, r.stderr
    (newer,) = set(tmp_path.glob("bank-*.ppbank")) - {entry, foreign, damaged}
    newer.unlink()  # (this version's: the counts below are of the first entry)
    assert pprender.prune_cache(path=tmp_path) == {"removed": 2, "bytes": gone, "kept": 1}
    assert entry.exists() and mine.exists() and not foreign.exists() and not damaged.exists()
    again, err = _in_new_process(tmp_path)
    np.testing.assert_array_equal(again, values)
    assert "tracing" not in err, err
    assert pprender.prune_cache(all=True, path=str(tmp_path)) == {"removed": 1, "bytes": len(good), "kept": 0}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    assert pprender.prune_cache(path=tmp_path / "absent") == {"removed": 0, "bytes": 0, "kept": 0}
    with pytest.raises(pprender.Error, match="all"):
        pprender.prune_cache(all="yes", path=tmp_path)  # type: ignore[arg-type]
    with pytest.raises(pprender.Error, match="path"):
        pprender.prune_cache(path=mine)


def test_no_disk_cache(tmp_path: Path) -> None:
    """``PPRENDER_CACHE_DIR=""`` (or ``set_cache_dir(None)``) keeps banks in memory only."""
    env = dict(os.environ, PPRENDER_CACHE_DIR="", PPRENDER_PROGRESS="0", HOME=str(tmp_path),
               XDG_CACHE_HOME=str(tmp_path))
    r = subprocess.run([sys.executable, "-c", "import pprender; print(pprender.cache_dir())"],
                       capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "None", r.stdout + r.stderr
    env.pop("PPRENDER_CACHE_DIR")
    r = subprocess.run([sys.executable, "-c", "import pprender; print(pprender.cache_dir())"],
                       capture_output=True, text=True, env=env, timeout=60)
    assert r.stdout.strip() == str(tmp_path / "pprender"), r.stdout + r.stderr
    old = pprender.cache_dir()
    try:
        pprender.set_cache_dir(None)
        assert pprender.cache_dir() is None
        pprender.set_cache_dir(str(tmp_path / "new" / "dir"))
        assert pprender.cache_dir() == tmp_path / "new" / "dir"
    finally:
        pprender.set_cache_dir(old)


def test_the_session_does_not_use_the_users_cache() -> None:
    """conftest.py points the whole session at a fresh temporary directory."""
    d = pprender.cache_dir()
    assert d is not None and d.name.startswith("pprender-test-cache-")


@pytest.mark.parametrize("bad", ["", 3, 1.5, "FILE"])
def test_set_cache_dir_names_the_parameter(tmp_path: Path, bad: object) -> None:
    if bad == "FILE":
        bad = tmp_path / "a-file"
        bad.write_text("x")
    old = pprender.cache_dir()
    with pytest.raises(pprender.Error, match="cache_dir"):
        pprender.set_cache_dir(bad)  # type: ignore[arg-type]
    assert pprender.cache_dir() == old


# ------------------------------------------------- PPRENDER_BANK_RAYS (Material's default)

BANK_RAYS_SCRIPT = """
import pprender
m = pprender.Material("beckmann", alpha=0.3, eta=1.5, terms=("single",))
print(m.bank_rays)
print(pprender.Material("beckmann", alpha=0.3, eta=1.5, terms=("single",), bank_rays=5000).bank_rays)
"""


def _bank_rays_in_new_process(value: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("PPRENDER_BANK_RAYS", None)
    if value is not None:
        env["PPRENDER_BANK_RAYS"] = value
    return subprocess.run([sys.executable, "-c", BANK_RAYS_SCRIPT], env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("value, expected", [(None, 4_000_000), ("", 4_000_000), ("1000", 1000),
                                             (" 250000 ", 250_000)])
def test_bank_rays_default_from_the_environment(value: str | None, expected: int) -> None:
    """Without ``bank_rays`` a Material takes PPRENDER_BANK_RAYS, else 4e6; a given value
    wins over both."""
    r = _bank_rays_in_new_process(value)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == [str(expected), "5000"]


@pytest.mark.parametrize("value", ["999", str(2**32 + 1), "2e5", "-5", "many"])
def test_bad_bank_rays_environment_is_refused(value: str) -> None:
    """A PPRENDER_BANK_RAYS out of [1000, 2^32] or not an integer: pprender.Error naming
    the variable and the range, never a silent default."""
    r = _bank_rays_in_new_process(value)
    assert r.returncode != 0
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("pprender.Error") or last.startswith("pprender._core.Error"), last
    assert "PPRENDER_BANK_RAYS" in last and "[1000, 2^32]" in last, last


def test_the_session_uses_small_banks() -> None:
    """conftest.py sets 2e5 rays for the banks the session's materials build by default."""
    assert pprender.Material("beckmann", alpha=0.3, eta=1.5, terms=("single",)).bank_rays == 200_000
