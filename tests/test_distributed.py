"""pprender.distributed: database builds on a Dask cluster.

Every build is compared with the single-process pprender.database.build_database of the
same database, bit for bit: every array of the Zarr store (profiles, flags, coordinates,
meshes) and every attribute but the creation time. Databases are tiny (sphere + 1U
CubeSat x 2 materials x 24 attitudes at resolution 32, chunks of 6: 16 chunks) and the
clusters are local: worker processes with one thread and one lavapipe thread each.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

import pprender as pp
from pprender import database, materials, models, so3
from pprender.distributed import BuildSummary, build_database_distributed, describe_workers

N_ATT = 24
CHUNK = 6  # 4 attitude chunks per (shape, material): 16 chunks
N_CHUNKS = 16


@pytest.fixture(scope="module")
def setup() -> dict:
    return {
        "shapes": {"sphere": models.sphere(0.1, 2), "1U": models.cubesat("1U", detail=1)},
        "materials": {"aluminium": materials.get("aluminium"), "white_paint": materials.get("white_paint")},
        "attitudes": so3.grid(N_ATT),
        "sensor": pp.Lidar(resolution=32),
    }


def _args(setup: dict) -> tuple:
    return setup["shapes"], setup["materials"], setup["attitudes"], setup["sensor"]


KW = {"chunk_attitudes": CHUNK, "attitude_grid": {"method": "so3.grid", "n": N_ATT}}


@pytest.fixture(scope="module")
def ref(tmp_path_factory, setup) -> Path:
    """The single-process build (in this process: lavapipe with its default threads)."""
    path = tmp_path_factory.mktemp("ref") / "ref.zarr"
    database.build_database(path, *_args(setup), progress=False, **KW)
    return path


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, env={"LP_NUM_THREADS": "1"},
                      dashboard_address=":0") as cluster, Client(cluster, set_as_default=False) as c:
        yield c


def _arrays(group, prefix: str = "") -> dict:
    out = {}
    for name, a in group.arrays():
        out[prefix + name] = (a.dtype, a.shape, a.chunks, dict(a.attrs), a[...])
    for name, g in group.groups():
        out.update(_arrays(g, prefix + name + "/"))
    return out


def assert_same_store(path: Path | str, ref_path: Path) -> None:
    """Every array bit for bit (NaN patterns included) and every attribute but
    ``created``."""
    g, r = zarr.open_group(str(path), mode="r"), zarr.open_group(str(ref_path), mode="r")
    a, b = _arrays(g), _arrays(r)
    assert sorted(a) == sorted(b)
    assert {"profile", "complete", "quaternion", "range", "_build/shape_1_faces"} <= set(a)
    for k in a:
        (dt, shp, ch, at, x), (dt2, shp2, ch2, at2, y) = a[k], b[k]
        assert (dt, shp, ch, at) == (dt2, shp2, ch2, at2), k
        x, y = np.asarray(x), np.asarray(y)
        if x.dtype.kind in "fc":
            assert x.tobytes() == y.tobytes(), k  # bit for bit
        else:
            assert np.array_equal(x, y), k
    strip = lambda d: {k: v for k, v in d.items() if k != "created"}  # noqa: E731
    assert strip(dict(g.attrs)) == strip(dict(r.attrs))
    assert np.asarray(g["complete"][...]).all()


def _check_summary(s: BuildSummary, written: int) -> None:
    assert s.chunks_total == N_CHUNKS and s.chunks_written == written
    assert s.chunks_skipped == N_CHUNKS - written
    assert sum(w.chunks for w in s.workers) == written == len([c for c in s.chunks if c.written])
    assert s.realizations == sum(w.realizations for w in s.workers) == sum(c.realizations for c in s.chunks)
    assert s.wall_seconds > 0 and s.realizations_per_second > 0


# --------------------------------------------------------------------------- tests


def test_default_local_cluster_builds_the_single_process_database(setup, ref, tmp_path, capfd) -> None:
    s = build_database_distributed(tmp_path / "d.zarr", *_args(setup), n_workers=2, progress=True, **KW)
    assert_same_store(s.path, ref)
    assert s.path == str(tmp_path / "d.zarr")
    _check_summary(s, N_CHUNKS)
    assert s.realizations == 2 * 2 * N_ATT
    # both worker processes rendered (16 tasks on 2 idle workers), none was this process
    assert len(s.workers) == 2 and all(w.chunks > 0 and w.realizations_per_second > 0 for w in s.workers)
    assert len({c.pid for c in s.chunks}) == 2 and os.getpid() not in {c.pid for c in s.chunks}
    assert s.dashboard_link is not None and s.dashboard_link.startswith("http")
    err = capfd.readouterr().err
    assert f"Dask dashboard at {s.dashboard_link}" in err and f"{N_CHUNKS}/{N_CHUNKS}" in err  # link, tqdm bar
    table = s.table()
    assert all(w.worker in table for w in s.workers) and f"| {s.realizations} |" in table
    # the default local cluster is closed afterwards: a second identical call skips everything
    again = build_database_distributed(tmp_path / "d.zarr", *_args(setup), n_workers=1, progress=False, **KW)
    assert again.chunks_skipped == N_CHUNKS and again.chunks == ()


def test_workers_use_this_checkout_and_one_lavapipe_thread(client) -> None:
    info = describe_workers(client)
    assert len(info) == 2 and len({i["pid"] for i in info.values()} | {os.getpid()}) == 3
    for i in info.values():
        assert i["pprender_file"] == pp.__file__ and i["pprender_version"] == pp.__version__
        # LP_NUM_THREADS reached the worker before its Vulkan driver loaded: lavapipe
        # started one render thread (two without it on this 2-core machine)
        assert i["LP_NUM_THREADS"] == "1" and i["llvmpipe_threads"] == 1, i
        assert i["device"]["device_type"] == "Cpu"


class DieOnce:
    """A render that kills its own worker process (SIGKILL, as the OOM killer would) in
    the middle of one chosen chunk, once (a marker file): it renders, writes garbage over
    the chunk's profiles in the store, and dies before the chunk's complete flag."""

    def __init__(self, path: str, marker: str, n_faces: int, material: str, first_attitude: np.ndarray) -> None:
        self.path, self.marker = path, marker
        self.n_faces, self.material, self.first = n_faces, material, first_attitude

    def __call__(self, scene, sensor, q):
        r = pp.render(scene, sensor, q, outputs=("profile",))
        if scene.n_faces == self.n_faces and scene.materials[0].name == self.material and np.array_equal(q[0], self.first):
            try:
                fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return r  # the retry
            g = zarr.open_group(self.path, mode="r+")
            s = list(g["shape"][...]).index("1U")
            m = list(g["material"][...]).index(self.material)
            start = int(np.flatnonzero((np.asarray(g["quaternion"][...]) == q[0]).all(axis=1))[0])
            g["profile"][s, m, start : start + len(q)] = 7.0  # a half-written chunk
            os.write(fd, f"{os.getpid()} {s} {m} {start}".encode())
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
        return r


def _gone(pid: int, timeout: float = 30.0) -> bool:
    """The process `pid` has exited: no such process, or a zombie its parent (the nanny) has
    not reaped yet (under load the build can return before it does; `os.kill(pid, 0)`
    succeeds on a zombie: a fresh clone's `make test` failed on this once). Polled for up
    to `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            return True
        if state in ("Z", "X"):
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.2)


def test_worker_killed_mid_chunk(setup, ref, client, tmp_path) -> None:
    client.wait_for_workers(2, timeout=60)
    path, marker = tmp_path / "k.zarr", tmp_path / "killed"
    target = 9  # flat index in build order: shape 1 (1U), material 0 (aluminium), attitudes 6:12
    die = DieOnce(str(path), str(marker), len(setup["shapes"]["1U"].faces), "aluminium", setup["attitudes"][CHUNK])
    s = build_database_distributed(path, *_args(setup), client=client, render=die, progress=False, **KW)
    pid, *where = map(int, marker.read_text().split())  # the worker wrote garbage, then died
    assert where == [1, 0, CHUNK]
    assert _gone(pid), f"worker {pid} still running"  # that worker process is gone
    (redo,) = [c for c in s.chunks if c.index == target]
    assert redo.written and redo.pid != pid  # rendered again by a live worker
    assert len(s.chunks) == N_CHUNKS and sorted(c.index for c in s.chunks) == list(range(N_CHUNKS))
    _check_summary(s, N_CHUNKS)
    assert_same_store(path, ref)  # the garbage was overwritten
    client.wait_for_workers(2, timeout=60)  # the nanny restarted the killed worker


def test_resume_skips_complete_chunks(setup, ref, client, tmp_path) -> None:
    client.wait_for_workers(2, timeout=60)
    path = tmp_path / "r.zarr"
    assert database.create_database(path, *_args(setup), **KW)
    done = [0, 5, 6, 15]
    for i in done:
        database.write_chunk(path, i)
    # through the scheduler's address this time (a connection of its own, closed afterwards)
    address = client.scheduler.address
    s = build_database_distributed(path, *_args(setup), scheduler_address=address, progress=False, **KW)
    _check_summary(s, N_CHUNKS - len(done))
    assert len(s.workers) >= 1 and all(w.worker in client.scheduler_info()["workers"] for w in s.workers)
    assert sorted(c.index for c in s.chunks) == sorted(set(range(N_CHUNKS)) - set(done))
    assert_same_store(path, ref)
    again = build_database_distributed(path, *_args(setup), client=client, progress=False, **KW)
    assert again.chunks == () and again.chunks_skipped == N_CHUNKS and again.realizations == 0


class FailChunk:
    """A render that raises for one chunk (attitudes starting at ``first``) of one shape."""

    def __init__(self, n_faces: int, first: np.ndarray) -> None:
        self.n_faces, self.first = n_faces, first

    def __call__(self, scene, sensor, q):
        if scene.n_faces == self.n_faces and np.array_equal(q[0], self.first):
            raise RuntimeError("simulated render failure")
        return pp.render(scene, sensor, q, outputs=("profile",))


def test_failing_chunk_raises_after_the_others_are_written(setup, ref, client, tmp_path) -> None:
    client.wait_for_workers(2, timeout=60)
    path = tmp_path / "f.zarr"
    fail = FailChunk(len(setup["shapes"]["sphere"].faces), setup["attitudes"][3 * CHUNK])  # chunks 3 and 7
    with pytest.raises(pp.Error, match=r"2 of 16 chunks failed after 1 retries.*simulated render failure"):
        build_database_distributed(path, *_args(setup), client=client, render=fail, retries=1, progress=False, **KW)
    assert [c.done for c in database.list_chunks(path)] == [i not in (3, 7) for i in range(N_CHUNKS)]
    s = build_database_distributed(path, *_args(setup), client=client, progress=False, **KW)
    assert sorted(c.index for c in s.chunks) == [3, 7]
    assert_same_store(path, ref)


def _silent_server() -> tuple[socket.socket, list[socket.socket], str]:
    """A TCP port that accepts connections and never answers (a wrong service)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    conns: list[socket.socket] = []

    def accept() -> None:
        try:
            while True:
                conns.append(srv.accept()[0])
        except OSError:
            pass

    threading.Thread(target=accept, daemon=True).start()
    return srv, conns, f"tcp://127.0.0.1:{srv.getsockname()[1]}"


def test_bad_scheduler_addresses_raise_quickly(setup, client, tmp_path) -> None:
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    free_port = closed.getsockname()[1]
    closed.close()  # nothing listens there now
    srv, conns, silent = _silent_server()
    worker = next(iter(client.scheduler_info()["workers"]))
    cases = {
        "garbage": "cannot reach",  # no port
        "foo://host:1": "cannot reach",  # unknown scheme
        "tcp://": "cannot reach",
        "": "a string such as",
        f"tcp://127.0.0.1:{free_port}": "cannot reach",  # connection refused
        silent: "no answer within 1.0 s",  # accepts, never answers
        worker: "not a Dask scheduler",  # a worker, not the scheduler
    }
    try:
        for address, msg in cases.items():
            path = tmp_path / "never.zarr"
            t0 = time.perf_counter()
            with pytest.raises(pp.Error, match=rf"scheduler_address = '{re.escape(address)}'.*({msg})"):
                build_database_distributed(path, *_args(setup), scheduler_address=address, connect_timeout=1.0,
                                           progress=False, **KW)
            # bounded: connect_timeout (1 s) + 1 s for the silent port; 3 s margin for load
            assert time.perf_counter() - t0 < 5.0, address
            assert not path.exists()  # nothing created before the cluster answered
    finally:
        for s in [srv, *conns]:
            s.close()
    with pytest.raises(pp.Error, match="not both"):
        build_database_distributed(tmp_path / "x", *_args(setup), client=client, scheduler_address="tcp://a:1")
    with pytest.raises(pp.Error, match="n_workers.*only to the local cluster"):
        build_database_distributed(tmp_path / "x", *_args(setup), client=client, n_workers=2)
    with pytest.raises(pp.Error, match="connect_timeout"):
        build_database_distributed(tmp_path / "x", *_args(setup), scheduler_address="tcp://a:1", connect_timeout=0)
    with pytest.raises(pp.Error, match="threads_per_worker"):
        build_database_distributed(tmp_path / "x", *_args(setup), threads_per_worker=0)
