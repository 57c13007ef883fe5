"""Build candidate databases on a Dask cluster: one task per chunk, written by the workers.

:func:`build_database_distributed` makes the same Zarr store as
:func:`pprender.database.build_database`, bit for bit when the workers render on the same
kind of device as the single process would (the layout, resumption and attributes are
those of :mod:`pprender.database`). The store is created on the client (its metadata, the
meshes and one probe render per shape for the range grid), then every chunk not yet
complete becomes one Dask task that calls :func:`pprender.database.write_chunk` on a
worker: the worker rebuilds the scene from the store, renders on its own device and
writes its own Zarr chunk file, then its ``complete`` flag. Profiles never travel through
the scheduler; a task returns a :class:`ChunkReport` of a few numbers.

Failures
--------
* A worker that dies mid-chunk (killed, out of memory, node lost) loses only that chunk:
  the scheduler reassigns the tasks of a lost worker (a task is given up after it has
  been running on ``distributed.scheduler.allowed-failures`` + 1 = 4 dying workers, Dask's
  default). Whatever the dead worker wrote of the chunk is overwritten, because its
  ``complete`` flag is written only after its data.
* A task that raises is retried ``retries`` times (any worker); chunks that still fail
  are reported in one :class:`pprender.Error` after all other chunks have been written.
* Interrupted builds (Ctrl-C, client lost) resume: running the same call again skips the
  complete chunks and submits only the rest.

Running on a real cluster
-------------------------
The store must be on a file system that the client and every worker see at the same
path (NFS, Lustre, GPFS, ...); ``path`` is made absolute on the client. Workers must
import the same pprender version as the client (checked before submitting).

Start one worker per GPU, one thread each, so that each worker renders on its own
device::

    dask scheduler --port 8786                      # on the head node
    # on each GPU node, once per GPU i (one process, one thread):
    CUDA_VISIBLE_DEVICES=i dask worker tcp://head:8786 --nworkers 1 --nthreads 1

then ``build_database_distributed(path, ..., scheduler_address="tcp://head:8786")``.
The renderer is Vulkan (wgpu) and takes the first high-performance adapter it sees;
``CUDA_VISIBLE_DEVICES`` hides devices from CUDA but the NVIDIA Vulkan driver is not
documented to honour it, so give each worker its own device by isolation: Slurm
``--gpus-per-task=1`` with ``ConstrainDevices=yes`` in ``cgroup.conf``, or one container
per GPU (``docker run --gpus device=i``). Check what each worker renders on with
:func:`describe_workers`. With dask-jobqueue::

    from dask_jobqueue import SLURMCluster
    cluster = SLURMCluster(cores=1, processes=1, memory="16GB",
                           job_extra_directives=["--gpus-per-task=1"])
    cluster.scale(jobs=8)                           # 8 GPUs
    client = Client(cluster)
    build_database_distributed(path, ..., client=client)

Without ``client`` or ``scheduler_address`` a :class:`distributed.LocalCluster` is
started on this machine (worker processes with one thread each; on CPU-only machines each
worker's lavapipe renderer gets ``LP_NUM_THREADS`` = cores // workers threads).
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import os
import sys
import threading
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._core import Error
from .database import (
    DEFAULT_CHUNK_ATTITUDES,
    RenderFn,
    _create,
    _progress,
    _Store,
    _write_chunk,
    list_chunks,
    open_database,
)
from ..lidar import Lidar

__all__ = [
    "BuildSummary",
    "ChunkReport",
    "WorkerThroughput",
    "build_database_distributed",
    "describe_workers",
]

#: Seconds to wait for a scheduler to answer before raising :class:`pprender.Error`.
DEFAULT_CONNECT_TIMEOUT = 10.0


@dataclasses.dataclass(frozen=True)
class ChunkReport:
    """What one chunk task returns (a few numbers; the profiles stay in the store).

    Attributes
    ----------
    index : int
        Flat chunk index in build order (:func:`pprender.database.list_chunks`).
    shape, material, attitude_chunk : int
        The chunk's indices.
    realizations : int
        Profiles rendered (attitudes in the chunk; 0 if it was already complete).
    seconds : float
        Time in the task (opening the store, building materials, render, write).
    setup_seconds : float
        Of which opening the store and building the scene (materials: ~0.5 s each, once
        per worker process).
    cpu_seconds : float
        CPU time of the worker process (all its threads, e.g. lavapipe's) during the
        task; ``cpu_seconds / seconds`` below the worker's expected cores means it waited
        for the CPU (other processes).
    worker : str
        Address of the worker that ran it.
    pid : int
        Its process id.
    written : bool
        False if the chunk was already complete (another attempt had written it).
    """

    index: int
    shape: int
    material: int
    attitude_chunk: int
    realizations: int
    seconds: float
    setup_seconds: float
    cpu_seconds: float
    worker: str
    pid: int
    written: bool


@dataclasses.dataclass(frozen=True)
class WorkerThroughput:
    """One worker's share of a build.

    Attributes
    ----------
    worker : str
        Worker address.
    chunks, realizations : int
        Chunks written and profiles rendered by it.
    busy_seconds : float
        Sum of its task times.
    setup_seconds : float
        Of which store opening and scene/material building.
    cpu_seconds : float
        CPU time of the worker process during its tasks (all threads).
    """

    worker: str
    chunks: int
    realizations: int
    busy_seconds: float
    setup_seconds: float
    cpu_seconds: float

    @property
    def realizations_per_second(self) -> float:
        """Profiles per second of busy time (the worker's own rate)."""
        return self.realizations / self.busy_seconds if self.busy_seconds > 0 else math.nan


@dataclasses.dataclass(frozen=True)
class BuildSummary:
    """Result of :func:`build_database_distributed`.

    Attributes
    ----------
    path : str
        Absolute path of the store (open it with :meth:`open`).
    dashboard_link : str or None
        The Dask dashboard (None if the scheduler has none).
    chunks_total, chunks_skipped, chunks_written : int
        All chunks, those complete before this call, those written by it.
    realizations : int
        Profiles rendered by this call.
    wall_seconds : float
        From the first task submitted to the last result received.
    setup_seconds : float
        Before that: starting or connecting to the cluster, creating the store, checking
        the workers.
    workers : tuple of WorkerThroughput
        Per worker, sorted by address.
    chunks : tuple of ChunkReport
        Per task, in completion order.
    """

    path: str
    dashboard_link: str | None
    chunks_total: int
    chunks_skipped: int
    chunks_written: int
    realizations: int
    wall_seconds: float
    setup_seconds: float
    workers: tuple[WorkerThroughput, ...]
    chunks: tuple[ChunkReport, ...]

    @property
    def realizations_per_second(self) -> float:
        """Profiles rendered per second of wall time (all workers together)."""
        return self.realizations / self.wall_seconds if self.wall_seconds > 0 else math.nan

    def table(self) -> str:
        """A markdown table of the per-worker throughput and the total."""
        lines = [
            "| worker | chunks | realizations | busy s | of which setup s | CPU s / busy s | realizations/s (busy) |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        for w in self.workers:
            cpu = w.cpu_seconds / w.busy_seconds if w.busy_seconds > 0 else math.nan
            lines.append(
                f"| {w.worker} | {w.chunks} | {w.realizations} | {w.busy_seconds:.2f} | "
                f"{w.setup_seconds:.2f} | {cpu:.2f} | {w.realizations_per_second:.1f} |"
            )
        lines.append(
            f"| **all** (wall {self.wall_seconds:.2f} s) | {self.chunks_written} | {self.realizations} | | | | "
            f"{self.realizations_per_second:.1f} |"
        )
        return "\n".join(lines)

    def open(self) -> Any:
        """The database as an :class:`xarray.Dataset` (:func:`pprender.database.open_database`)."""
        return open_database(self.path)


# --------------------------------------------------------------------------- worker side


def _write_chunk_task(path: str, index: int, render: RenderFn | None) -> ChunkReport:
    """The Dask task: render and write chunk ``index`` of the store at ``path``."""
    t0, c0 = time.perf_counter(), time.process_time()
    st = _Store(path)
    c = st.chunk(index)
    if not c.done:
        st.scene(c.shape, c.material)  # materials are built here (cached per process)
    t1 = time.perf_counter()
    written = _write_chunk(st, c, render)
    t2, c2 = time.perf_counter(), time.process_time()
    return ChunkReport(
        index=int(index),
        shape=c.shape,
        material=c.material,
        attitude_chunk=c.attitude_chunk,
        realizations=(c.stop - c.start) if written else 0,
        seconds=t2 - t0,
        setup_seconds=t1 - t0,
        cpu_seconds=c2 - c0,
        worker=_worker_address(),
        pid=os.getpid(),
        written=written,
    )


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except ValueError:  # not in a worker
        return f"pid {os.getpid()}"


def _worker_probe(path: str | None, device: bool) -> dict[str, Any]:
    """What a worker runs with: pprender location and version, whether it sees the
    store, and (``device``) the adapter it renders on and its lavapipe threads."""
    import pprender

    out: dict[str, Any] = {
        "pprender_file": pprender.__file__,
        "pprender_version": pprender.__version__,
        "pid": os.getpid(),
        "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
        "CUDA_VISIBLE_DEVICES": os.environ.get("CUDA_VISIBLE_DEVICES"),
    }
    if path is not None:
        out["sees_store"] = os.path.isfile(os.path.join(path, "zarr.json"))
    if device:
        out["device"] = pprender.device_info()
        # lavapipe's render threads are named llvmpipe-<i> (none on a GPU)
        try:
            tasks = os.listdir("/proc/self/task")
            names = []
            for t in tasks:
                try:
                    with open(f"/proc/self/task/{t}/comm") as f:
                        names.append(f.read().strip())
                except OSError:
                    pass
            out["llvmpipe_threads"] = sum(n.startswith("llvmpipe") for n in names)
        except OSError:
            out["llvmpipe_threads"] = None
    return out


def describe_workers(client: Any, *, path: str | os.PathLike[str] | None = None) -> dict[str, dict[str, Any]]:
    """What each worker of ``client`` renders with.

    Opens the render device on every worker (as its first chunk would).

    Parameters
    ----------
    client : distributed.Client
        A connected client.
    path : str or os.PathLike, optional
        A database path to look for on every worker.

    Returns
    -------
    dict of str to dict
        Per worker address: ``pprender_file``, ``pprender_version``, ``pid``,
        ``LP_NUM_THREADS``, ``CUDA_VISIBLE_DEVICES``, ``device``
        (:func:`pprender.device_info`), ``llvmpipe_threads`` (lavapipe's render threads; 0 on
        a GPU) and, with ``path``, ``sees_store`` (whether the worker sees the store at that
        path).
    """
    p = None if path is None else os.path.abspath(os.fspath(path))
    return dict(client.run(_worker_probe, p, True))


# --------------------------------------------------------------------------- client side


def _probe_scheduler(address: str, timeout: float) -> None:
    """Raise :class:`pprender.Error` unless a Dask scheduler answers at ``address``
    within about ``timeout`` seconds (at most ``timeout`` + 1 s whatever answers, or
    does not)."""
    from distributed.comm.core import connect
    from distributed.core import send_recv

    async def identity() -> Any:
        comm = await connect(address, timeout=timeout)
        try:
            return await send_recv(comm, op="identity")
        finally:
            comm.abort()

    async def bounded() -> Any:
        # connect's own timeout does not bound the handshake (a port that accepts and
        # never answers would hang it): bound the whole probe.
        return await asyncio.wait_for(identity(), timeout + 1.0)

    # In a daemon thread: the caller may already run an event loop (Jupyter), and a
    # stuck probe must not keep the interpreter from exiting.
    out: dict[str, Any] = {}

    def probe() -> None:
        try:
            out["ident"] = asyncio.run(bounded())
        except BaseException as e:  # OSError, ValueError (malformed), TimeoutError, garbage frames, ...
            out["error"] = e

    thread = threading.Thread(target=probe, name="pprender-probe-scheduler", daemon=True)
    thread.start()
    thread.join(timeout + 5.0)
    if thread.is_alive() or isinstance(out.get("error"), (TimeoutError, asyncio.TimeoutError)):
        raise Error(
            f"invalid scheduler_address = {address!r}: no answer within {timeout} s "
            "(connect_timeout); is a Dask scheduler running there?"
        )
    if "error" in out:
        e = out["error"]
        raise Error(
            f"invalid scheduler_address = {address!r}: cannot reach a Dask scheduler "
            f"({type(e).__name__}: {e}); expected e.g. 'tcp://host:8786'"
        )
    ident = out["ident"]
    kind = ident.get("type") if isinstance(ident, Mapping) else None
    if kind != "Scheduler":
        raise Error(
            f"invalid scheduler_address = {address!r}: it answers, but as {kind!r}, not a Dask "
            "scheduler (pass the scheduler's address, e.g. 'tcp://host:8786', not a worker's)"
        )


def _connect(address: Any, timeout: float) -> Any:
    from distributed import Client

    if not isinstance(address, str) or not address.strip():
        raise Error(f"invalid scheduler_address = {address!r}: a string such as 'tcp://host:8786'")
    _probe_scheduler(address, timeout)
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except Exception as e:
        raise Error(f"invalid scheduler_address = {address!r}: cannot connect ({type(e).__name__}: {e})") from None


def _usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _check_positive_int(name: str, value: Any, allow_zero: bool = False) -> int:
    lo = 0 if allow_zero else 1
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise Error(f"invalid {name} = {value!r}: an integer >= {lo}")
    return value


def _summarize(reports: Sequence[ChunkReport]) -> tuple[WorkerThroughput, ...]:
    per: dict[str, list[ChunkReport]] = {}
    for r in reports:
        per.setdefault(r.worker, []).append(r)
    return tuple(
        WorkerThroughput(
            worker=w,
            chunks=sum(r.written for r in rs),
            realizations=sum(r.realizations for r in rs),
            busy_seconds=sum(r.seconds for r in rs),
            setup_seconds=sum(r.setup_seconds for r in rs),
            cpu_seconds=sum(r.cpu_seconds for r in rs),
        )
        for w, rs in sorted(per.items())
    )


def build_database_distributed(
    path: str | os.PathLike[str],
    shapes: Mapping[str, Any],
    materials: Mapping[str, Any],
    attitudes: Any,
    sensor: Lidar,
    *,
    chunk_attitudes: int = DEFAULT_CHUNK_ATTITUDES,
    range_window: float | None = None,
    dtype: str = "float32",
    attitude_grid: Any = None,
    render: RenderFn | None = None,
    progress: bool = True,
    overwrite: bool = False,
    client: Any = None,
    scheduler_address: str | None = None,
    n_workers: int | None = None,
    threads_per_worker: int = 1,
    worker_env: Mapping[str, str] | None = None,
    retries: int = 2,
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
) -> BuildSummary:
    """Render every shape x material x attitude into a Zarr database on a Dask cluster.

    One task per pending chunk, written by the workers. The store (and the result) is that of
    :func:`pprender.database.build_database` with the same arguments, bit for bit when the
    workers render on the same kind of device; an existing store made with the same
    parameters is resumed (its complete chunks are skipped), one made with other parameters
    raises unless ``overwrite=True``. See the module docstring for failures and for running
    on a cluster.

    Parameters
    ----------
    path : str or os.PathLike
        As :func:`pprender.database.build_database`. It must be on a file system that every
        worker sees at the same (absolute) path.
    shapes : Mapping[str, mesh]
        As :func:`pprender.database.build_database`.
    materials : Mapping[str, material]
        As :func:`pprender.database.build_database`.
    attitudes : array_like
        As :func:`pprender.database.build_database`.
    sensor : pprender.Lidar
        As :func:`pprender.database.build_database`.
    chunk_attitudes : int, optional
        As :func:`pprender.database.build_database`.
    range_window : float, optional
        As :func:`pprender.database.build_database`.
    dtype : {"float32", "float64"}, optional
        As :func:`pprender.database.build_database`.
    attitude_grid : JSON-serializable, optional
        As :func:`pprender.database.build_database`.
    render : callable, optional
        As :func:`pprender.database.build_database`; it is pickled to the workers, so it
        must be importable there (a module-level function or class).
    progress : bool, optional
        Print the dashboard link and show a tqdm bar (one step per chunk, as results
        arrive). Default True.
    overwrite : bool, optional
        As :func:`pprender.database.build_database`.
    client : distributed.Client, optional
        Use this client's cluster (left running).
    scheduler_address : str, optional
        Connect to the scheduler at this address (e.g. ``"tcp://head:8786"``); the
        connection is closed at the end, the cluster left running.
    n_workers : int, optional
        Local cluster only (neither ``client`` nor ``scheduler_address``): worker
        processes, default the number of usable cores.
    threads_per_worker : int, optional
        Local cluster only: threads per worker (1, the default: one chunk at a time per
        process).
    worker_env : Mapping[str, str], optional
        Local cluster only: environment variables of the worker processes, over the
        default ``{"LP_NUM_THREADS": str(max(1, cores // (n_workers * threads_per_worker)))}``
        (lavapipe's render threads; ignored by GPUs).
    retries : int, optional
        Times a chunk task that raises is retried (worker deaths are handled separately by
        the scheduler, see the module docstring). Default 2.
    connect_timeout : float, optional
        Seconds to wait for ``scheduler_address`` to answer before raising. Default 10.

    Returns
    -------
    BuildSummary
        Path, dashboard link, chunk counts, wall time and per-worker throughput
        (``summary.table()``); ``summary.open()`` opens the database.

    Raises
    ------
    pprender.Error
        Invalid arguments, an unreachable or malformed ``scheduler_address`` (within about
        ``connect_timeout`` s), workers with another pprender version or that do not see
        the store, or chunks that failed after ``retries`` retries (the others are
        written; calling again retries the failed ones).
    """
    t_start = time.perf_counter()
    local = client is None and scheduler_address is None
    if client is not None and scheduler_address is not None:
        raise Error("invalid arguments: pass client or scheduler_address, not both")
    if not local:
        for name, given in (("n_workers", n_workers is not None), ("threads_per_worker", threads_per_worker != 1),
                            ("worker_env", worker_env is not None)):
            if given:
                raise Error(f"invalid {name}: it applies only to the local cluster (no client or scheduler_address)")
    if n_workers is not None:
        _check_positive_int("n_workers", n_workers)
    _check_positive_int("threads_per_worker", threads_per_worker)
    _check_positive_int("retries", retries, allow_zero=True)
    if isinstance(connect_timeout, bool) or not isinstance(connect_timeout, (int, float)) or not (
        math.isfinite(connect_timeout) and connect_timeout > 0
    ):
        raise Error(f"invalid connect_timeout = {connect_timeout!r}: positive seconds")
    if worker_env is not None and not (
        isinstance(worker_env, Mapping) and all(isinstance(k, str) and isinstance(v, str) for k, v in worker_env.items())
    ):
        raise Error("invalid worker_env: a mapping of environment variable names to string values")

    apath = os.path.abspath(os.fspath(path))
    own_client = None
    own_cluster = None
    try:
        # Connect first: a bad address fails before any rendering.
        if scheduler_address is not None:
            own_client = client = _connect(scheduler_address, float(connect_timeout))
        # The store, on the client (probe renders, metadata, meshes).
        _create(
            apath, shapes, materials, attitudes, sensor,
            chunk_attitudes=chunk_attitudes, range_window=range_window, dtype=dtype,
            attitude_grid=attitude_grid, render=render, overwrite=overwrite,
        )
        chunks = list_chunks(apath)
        index = {(c.shape, c.material, c.attitude_chunk): i for i, c in enumerate(chunks)}
        pending = [c for c in chunks if not c.done]
        if local:
            from distributed import Client, LocalCluster

            nw = n_workers if n_workers is not None else _usable_cores()
            env = {"LP_NUM_THREADS": str(max(1, _usable_cores() // (nw * threads_per_worker)))}
            env.update(worker_env or {})
            own_cluster = LocalCluster(
                n_workers=nw, threads_per_worker=threads_per_worker, processes=True, env=env,
            )
            own_client = client = Client(own_cluster, set_as_default=False)
        assert client is not None
        link = _dashboard_link(client)
        _check_workers(client, apath)
        if progress and link:
            print(f"pprender: Dask dashboard at {link}", file=sys.stderr)
        t_submit = time.perf_counter()
        reports = _run(client, apath, pending, index, render, retries, progress, len(chunks))
        t_end = time.perf_counter()
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
    return BuildSummary(
        path=apath,
        dashboard_link=link,
        chunks_total=len(chunks),
        chunks_skipped=len(chunks) - len(pending),
        chunks_written=sum(r.written for r in reports),
        realizations=sum(r.realizations for r in reports),
        wall_seconds=t_end - t_submit,
        setup_seconds=t_submit - t_start,
        workers=_summarize(reports),
        chunks=tuple(reports),
    )


def _dashboard_link(client: Any) -> str | None:
    try:
        return str(client.dashboard_link) if client.dashboard_link else None
    except Exception:  # no dashboard service
        return None


def _check_workers(client: Any, path: str) -> None:
    from .. import __version__

    info: dict[str, dict[str, Any]] = dict(client.run(_worker_probe, path, False))
    bad_version = {w: i["pprender_version"] for w, i in info.items() if i["pprender_version"] != __version__}
    if bad_version:
        raise Error(
            f"invalid cluster: workers run another pprender version than the client ({__version__}): "
            f"{bad_version}"
        )
    blind = sorted(w for w, i in info.items() if not i["sees_store"])
    if blind:
        raise Error(
            f"invalid path {path!r}: workers {blind} do not see the store; it must be on a file "
            "system shared by the client and all workers, at the same path"
        )


def _run(
    client: Any,
    path: str,
    pending: Sequence[Any],
    index: Mapping[tuple[int, int, int], int],
    render: RenderFn | None,
    retries: int,
    progress: bool,
    total: int,
) -> list[ChunkReport]:
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]
    # Futures are dropped as their results arrive, so that the scheduler forgets the
    # results (a lost worker's finished chunks are not recomputed for nothing).
    live = {}
    for c in pending:
        f = client.submit(
            _write_chunk_task, path, index[(c.shape, c.material, c.attitude_chunk)], render,
            key=f"pprender-chunk-{c.shape}-{c.material}-{c.attitude_chunk}-{token}",
            retries=retries, pure=False,
        )
        live[f.key] = f
    results = as_completed(list(live.values()), loop=client.loop)
    bar = _progress(progress, total=total, initial=total - len(pending), desc=Path(path).name)
    reports: list[ChunkReport] = []
    failed: list[tuple[str, BaseException]] = []
    try:
        for fut in results:
            del live[fut.key]
            try:
                reports.append(fut.result())
            except Exception as e:  # the task's exception, KilledWorker, CancelledError
                failed.append((str(fut.key), e))
            del fut
            bar.update(1)
    finally:
        bar.close()
        if live:  # interrupted: stop the rest
            client.cancel(list(live.values()))
    if failed:
        key, exc = failed[0]
        raise Error(
            f"{len(failed)} of {len(pending)} chunks failed after {retries} retries (the others are "
            f"written; calling again retries these); first: {key}: {type(exc).__name__}: {exc}"
        ) from exc
    return reports
