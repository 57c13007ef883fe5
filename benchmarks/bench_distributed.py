"""Distributed database build benchmark: realizations per second with 1 and 2 local workers.

``python benchmarks/bench_distributed.py [--write [PATH]] [--workers 1,2]`` builds the same
database (:func:`pprender.distributed.build_database_distributed`) once per worker count,
in one run, and prints a markdown report (``--write``: also to
``docs/distributed-benchmark.md``, or ``--write PATH``).

Database: a sphere (radius 0.1 m) and a 1U CubeSat (panels, antenna) x aluminium and
white paint x ``--attitudes`` attitudes of :func:`pprender.so3.grid`, Mueller profiles at
resolution ``--resolution``, chunks of ``--chunk`` attitudes. A realization is one
profile (one shape x material x attitude).

Each worker count gets a fresh :class:`distributed.LocalCluster` (worker processes, one
Dask thread and ``LP_NUM_THREADS=1`` each, so one core per worker on lavapipe) and a fresh
store. Times, in order:

* cluster: starting the cluster and connecting;
* store: creating the empty store on the client (probe renders, metadata, meshes);
* warm-up: on every worker, opening the Vulkan device (pipeline compilation) and building
  every material (~0.5 s each), i.e. what the first chunks of a cold worker pay; the
  longest worker's time;
* build: :func:`build_database_distributed` on the warm cluster, first task submitted
  to last result (``BuildSummary.wall_seconds``): the steady-state rate.

"End to end" adds them all: what a user of the default local cluster waits. Speedups
are relative to the first worker count. The stores of all worker counts are compared bit
for bit. Also measured: the scheduler's round trip per task (no-op tasks) and a chunk's
cost outside the renderer (store open, scene, padding, Zarr write; a stand-in render
returns stored profiles), the inputs of the N-GPU estimate written below the tables.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import statistics
import sys
import tempfile
import time
import types
from pathlib import Path
from typing import Any

import numpy as np

import pprender
from pprender import database, materials, models, so3
from bench import cpu_model, emit_report, load_average, threads_available
from pprender.distributed import BuildSummary, build_database_distributed, describe_workers

NAME = "distributed-benchmark.md"


def _setup(n_attitudes: int, resolution: int) -> dict[str, Any]:
    return {
        "shapes": {"sphere": models.sphere(0.1, 2), "1U": models.cubesat("1U", detail=1)},
        "materials": {"aluminium": materials.get("aluminium"), "white_paint": materials.get("white_paint")},
        "attitudes": so3.grid(n_attitudes),
        "sensor": pprender.Lidar(resolution=resolution),
    }


def _warm_worker(path: str) -> float:
    """On a worker: open the device and build every material (what a cold worker's first
    chunks pay); returns seconds."""
    t0 = time.perf_counter()
    st = database._Store(path)
    for s in range(len(st.shape_names)):
        for m in range(len(st.material_specs)):
            pprender.render(st.scene(s, m), st.sensor, st.attitudes[:1], outputs=("profile",))
    return time.perf_counter() - t0


def _cpu_jiffies() -> tuple[float, float]:
    """(busy, idle) CPU seconds of the whole machine so far (/proc/stat; NaN elsewhere):
    busy includes other users' processes and time stolen by the hypervisor."""
    try:
        with open("/proc/stat") as f:
            v = [float(x) for x in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return math.nan, math.nan
    tick = float(os.sysconf("SC_CLK_TCK"))
    user, nice, system, idle, iowait, irq, softirq, steal = v
    return (user + nice + system + irq + softirq + steal) / tick, (idle + iowait) / tick


def _noop(i: int) -> int:
    return i


def _scheduler_overhead(client: Any, n: int = 300) -> float:
    """Seconds per task of no-op tasks submitted together (round trip, all workers)."""
    client.gather(client.map(_noop, range(20), pure=False))  # warm
    t0 = time.perf_counter()
    client.gather(client.map(_noop, range(n), pure=False))
    return (time.perf_counter() - t0) / n


def _chunk_overhead(path: str, setup: dict[str, Any], chunk: int, tmp: Path, n: int = 6) -> tuple[float, int]:
    """Mean seconds of write_chunk outside the renderer, and bytes per chunk: a copy of
    the store's recipe is written with a stand-in render returning the stored profiles."""
    ds = database.open_database(path)
    grid = ds.attrs["range_grid"]
    K, w = int(grid["half_bins"]), float(grid["bin_width"])
    half = grid["shape_half_bins"]
    names = list(ds.shape.values)
    stored = {s: np.asarray(ds.profile.isel(shape=i, material=0).values[:chunk], dtype=np.float64)
              for i, s in enumerate(names)}

    def standin(scene: pprender.Scene, sensor: pprender.Lidar, q: np.ndarray) -> Any:
        s = "sphere" if scene.n_faces == len(setup["shapes"]["sphere"].faces) else "1U"
        k = int(half[s])
        return types.SimpleNamespace(profile=stored[s][: len(q), K - k : K + k],
                                     bin_edges=(np.arange(2 * k + 1) - k) * w)

    copy = tmp / "overhead.zarr"
    database.create_database(copy, setup["shapes"], setup["materials"], setup["attitudes"], setup["sensor"],
                             chunk_attitudes=chunk, render=standin)
    database.write_chunk(copy, 0, render=standin)  # warm (imports, material cache)
    times = []
    for i in range(1, min(n, len(database.list_chunks(copy)) - 1) + 1):
        t0 = time.perf_counter()
        database.write_chunk(copy, i, render=standin)
        times.append(time.perf_counter() - t0)
    nbytes = chunk * 2 * K * 16 * np.dtype(ds.profile.dtype).itemsize
    return statistics.median(times), nbytes


def _same_store(a: str, b: str) -> bool:
    import zarr

    ga, gb = zarr.open_group(a, mode="r"), zarr.open_group(b, mode="r")

    def arrays(g: Any, prefix: str = "") -> dict[str, np.ndarray]:
        out = {prefix + k: np.asarray(v[...]) for k, v in g.arrays()}
        for k, sub in g.groups():
            out.update(arrays(sub, prefix + k + "/"))
        return out

    xa, xb = arrays(ga), arrays(gb)
    if sorted(xa) != sorted(xb):
        return False
    for k in xa:
        x, y = xa[k], xb[k]
        same = x.tobytes() == y.tobytes() if x.dtype.kind in "fc" else np.array_equal(x, y)
        if not same:
            return False
    strip = lambda d: {k: v for k, v in dict(d).items() if k != "created"}  # noqa: E731
    return bool(strip(ga.attrs) == strip(gb.attrs))


def run(workers: list[int], n_attitudes: int, resolution: int, chunk: int, log: Any = sys.stderr) -> dict[str, Any]:
    """Build the benchmark database once per worker count; returns the measurements."""
    from distributed import Client, LocalCluster

    setup = _setup(n_attitudes, resolution)
    tmp = Path(tempfile.mkdtemp(prefix="pprender-bench-dist-"))
    rows: list[dict[str, Any]] = []
    extra: dict[str, Any] = {}
    try:
        # warm the client (device, imports) so that store creation costs the same each time
        database.create_database(tmp / "client-warm.zarr", setup["shapes"], setup["materials"],
                                 setup["attitudes"][:1], setup["sensor"])
        for n in workers:
            path = str(tmp / f"w{n}.zarr")
            print(f"[{n} worker(s)] starting the cluster", file=log)
            t0 = time.perf_counter()
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   env={"LP_NUM_THREADS": "1"}, dashboard_address=":0")
            client = Client(cluster, set_as_default=False)
            try:
                t_cluster = time.perf_counter() - t0
                t0 = time.perf_counter()
                database.create_database(path, setup["shapes"], setup["materials"], setup["attitudes"],
                                         setup["sensor"], chunk_attitudes=chunk,
                                         attitude_grid={"method": "so3.grid", "n": n_attitudes})
                t_store = time.perf_counter() - t0
                info = describe_workers(client, path=path)
                bad = {w: i for w, i in info.items() if i["llvmpipe_threads"] not in (0, 1) or not i["sees_store"]}
                if bad:
                    raise pprender.Error(f"benchmark workers not set up as intended: {bad}")
                warm = client.run(_warm_worker, path)
                t_warm = max(warm.values())
                print(f"[{n} worker(s)] building ({len(database.list_chunks(path))} chunks)", file=log)
                busy0, _ = _cpu_jiffies()
                own0 = time.process_time()
                s: BuildSummary = build_database_distributed(
                    path, setup["shapes"], setup["materials"], setup["attitudes"], setup["sensor"],
                    chunk_attitudes=chunk, attitude_grid={"method": "so3.grid", "n": n_attitudes},
                    client=client, progress=False,
                )
                busy = _cpu_jiffies()[0] - busy0
                own = time.process_time() - own0 + sum(w.cpu_seconds for w in s.workers)
                if n == max(workers):
                    extra["scheduler_s_per_task"] = _scheduler_overhead(client)
            finally:
                client.close()
                cluster.close()
            rows.append({
                "workers": n, "cluster": t_cluster, "store": t_store, "warm": t_warm, "summary": s,
                "end_to_end": t_cluster + t_store + t_warm + s.setup_seconds + s.wall_seconds,
                "devices": sorted({i["device"]["name"] for i in info.values()}),
                # cores in use on average during the build: by this benchmark's processes
                # (workers + client/scheduler), and by everything else on the machine
                "own_cores": own / s.wall_seconds,
                "other_cores": max(0.0, busy - own) / s.wall_seconds,
            })
            print(f"[{n} worker(s)] {s.realizations} realizations in {s.wall_seconds:.1f} s "
                  f"({s.realizations_per_second:.1f}/s)", file=log)
        first = str(tmp / f"w{workers[0]}.zarr")
        extra["identical"] = all(_same_store(first, str(tmp / f"w{n}.zarr")) for n in workers[1:])
        extra["chunk_overhead_s"], extra["chunk_bytes"] = _chunk_overhead(first, setup, chunk, tmp)
        grid = database.open_database(first).attrs["range_grid"]
        extra["bins"] = int(grid["n_bins"])
        t_mat = []
        for m in setup["materials"].values():
            params = database._material_params(m)
            t0 = time.perf_counter()
            database._material_from_params(params)
            t_mat.append(time.perf_counter() - t0)
        extra["material_s"] = statistics.median(t_mat)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"rows": rows, "setup": setup, "chunk": chunk, "resolution": resolution, **extra}


def report(res: dict[str, Any], load_start: str, load_end: str, total: float) -> str:
    rows = res["rows"]
    setup = res["setup"]
    base = rows[0]
    n_real = base["summary"].realizations
    out = [
        "# Distributed database build benchmark",
        "",
        "`python benchmarks/bench_distributed.py` (module docstring: method). Local Dask cluster on one machine; "
        "each worker is a process with one Dask thread and `LP_NUM_THREADS=1` (one lavapipe render thread).",
        "",
        f"- Machine: {cpu_model()}, {threads_available()} threads; render device {', '.join(base['devices'])}; "
        f"load average at start {load_start}, at end {load_end} (other jobs share this machine); total run {total:.0f} s.",
        f"- Database: {len(setup['shapes'])} shapes x {len(setup['materials'])} materials x "
        f"{len(setup['attitudes'])} attitudes = {n_real} realizations (Mueller profiles, {res['bins']} range bins, "
        f"resolution {res['resolution']}), {base['summary'].chunks_total} chunks of {res['chunk']} attitudes; "
        f"pprender {pprender.__version__}.",
        f"- The stores built with {', '.join(str(r['workers']) for r in rows)} worker(s) are bit-for-bit identical: "
        f"{'yes' if res['identical'] else 'NO'}.",
        "",
        "Steady state (warm workers: device open, materials built):",
        "",
        "| workers | build wall s | realizations/s | speedup | cores used by the benchmark | cores used by other processes |",
        "| ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        s = r["summary"]
        out.append(f"| {r['workers']} | {s.wall_seconds:.1f} | {s.realizations_per_second:.1f} | "
                   f"{s.realizations_per_second / base['summary'].realizations_per_second:.2f}x | "
                   f"{r['own_cores']:.2f} | {r['other_cores']:.2f} |")
    out += [
        "",
        f"Cores: average over the build of the CPU time of the workers and of this process (client, "
        f"scheduler), and of the rest of the machine's busy time (/proc/stat, including hypervisor steal); "
        f"the machine has {threads_available()}.",
    ]
    out += [
        "",
        "End to end (cluster start + store creation + worker warm-up + build):",
        "",
        "| workers | cluster s | store s | warm-up s (slowest worker) | build s | total s | realizations/s | speedup |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        s = r["summary"]
        rate = s.realizations / r["end_to_end"]
        out.append(f"| {r['workers']} | {r['cluster']:.1f} | {r['store']:.1f} | {r['warm']:.1f} | "
                   f"{s.setup_seconds + s.wall_seconds:.1f} | {r['end_to_end']:.1f} | {rate:.1f} | "
                   f"{rate / (n_real / base['end_to_end']):.2f}x |")
    if len(rows) > 1:
        last = rows[-1]
        per = lambda r: r["summary"].realizations_per_second / r["workers"]  # noqa: E731
        cpu = lambda r: sum(w.cpu_seconds for w in r["summary"].workers) / sum(  # noqa: E731
            w.busy_seconds for w in r["summary"].workers)
        out += [
            "",
            f"Per worker, {last['workers']} workers render at {per(last) / per(base):.2f} of the single worker's "
            f"rate; their processes used {cpu(last):.2f} CPU s per busy s against {cpu(base):.2f} for the single "
            "worker (above 1: its Python and lavapipe threads ran in parallel at times, on the free core), and "
            "the client and scheduler share the same two cores. Warm-up (device, materials) and cluster start "
            "are fixed costs per worker: they lower the end-to-end speedup of this short build and are "
            "amortized in long ones.",
        ]
    for r in rows:
        out += ["", f"Per worker, {r['workers']} worker(s) (busy: sum of task times; setup: store open + scene; "
                "CPU: the worker process's CPU time, all threads):", "",
                r["summary"].table()]
    chunk_mb = res["chunk_bytes"] / 1e6
    out += [
        "",
        "Overheads measured in the same run:",
        "",
        f"- Scheduler round trip: {res['scheduler_s_per_task'] * 1e3:.2f} ms per task "
        f"(no-op tasks, {rows[-1]['workers']} workers).",
        f"- A chunk outside the renderer (store open, scene from cached materials, padding, float32 Zarr write of "
        f"{chunk_mb:.2f} MB + its flag): {res['chunk_overhead_s'] * 1e3:.1f} ms (median of up to 6, local disk).",
        f"- Material build (tables): {res['material_s']:.2f} s per material, once per worker process (part of the "
        "warm-up above).",
        "",
        ESTIMATE,
    ]
    return "\n".join(out) + "\n"


ESTIMATE = """## Paper estimate on N GPUs (not measured)

No GPU measurement exists yet. Symbols:

- `R_gpu`: realizations per second of one GPU for the database's sensor and shapes,
  **not measured** (measure it with `python benchmarks/bench_render.py --device gpu`, profile
  only, at the database's resolution).
- `A`: attitudes per chunk (default 256); `B`: range bins; a chunk is `A x B x 16 x 4` bytes
  of float32 Mueller profiles (`A x B x 4 x 4` for Stokes).
- `t_o`: a chunk's cost outside the renderer (store open, scene, padding, Zarr encode and
  write); measured above on local disk, a few to tens of ms; on a shared file system add the
  chunk's write time at one worker's bandwidth and the metadata latency of ~3 small files.
- `t_s`: scheduler round trip per task, 1-2 ms (measured above on this machine; Dask's
  documentation quotes ~1 ms of scheduler overhead per task), paid once per chunk.
- `t_w`: warm-up per worker: device creation and shader compilation (~0.5-1 s on lavapipe;
  GPU not measured) + `n_materials x 0.3-0.5 s` of material tables (built on the worker's
  CPU, not the GPU) + worker start (seconds; minutes if the batch queue is slow).
- `W`: aggregate write bandwidth of the shared file system (bytes/s).

Assumptions: one worker per GPU, one thread each, every GPU alike; chunks independent (no
communication between workers: each writes its own Zarr chunk file); the client's store
creation (one probe render per shape) is negligible; chunks are many more than workers, so
the last wave's imbalance is at most one chunk per worker.

Per worker, a chunk takes `t_c = A / R_gpu + t_o`. With `C` chunks, the build takes about

    T(N) = t_start + t_w + ceil(C / N) x t_c

and the steady throughput is the smallest of three limits:

    R(N) = min( N x A / t_c,            # GPUs
                W / (B x 64 bytes),     # shared file system (float32 Mueller)
                A / t_s )               # scheduler (A = 256, t_s = 2 ms: ~128k realizations/s)

Example with the symbol left in: at `A = 256`, `B = 200` (a chunk is 3.3 MB) and `t_o =
0.05 s` on a parallel file system, `t_c = 256 / R_gpu + 0.05 s`; the GPUs are the limit as
long as `N x R_gpu x 12.8 kB < W` (e.g. `W` = 1 GB/s allows `N x R_gpu` up to ~78,000
realizations/s) and `t_o` costs a fraction `0.05 R_gpu / 256` of the render time (5 % at
`R_gpu` = 256/s, 50 % at 2,560/s: raise `chunk_attitudes` for fast GPUs). A full database of
`S x M x M_att` realizations then takes about `S x M x M_att / R(N) + t_w + t_start`.
"""


def main(workers: list[int] | None = None, n_attitudes: int = 2560, resolution: int = 64, chunk: int = 128,
         write: bool | str | os.PathLike[str] = False, quiet: bool = False) -> str:
    """Run the benchmark and return (print, optionally write) the markdown report."""
    workers = workers or [1, 2]
    load_start = load_average()
    t0 = time.perf_counter()
    res = run(workers, n_attitudes, resolution, chunk, log=open(os.devnull, "w") if quiet else sys.stderr)
    text = report(res, load_start, load_average(), time.perf_counter() - t0)
    return emit_report(text, write, NAME, quiet)


def _cli(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python benchmarks/bench_distributed.py", description=__doc__.splitlines()[0])
    p.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    p.add_argument("--attitudes", type=int, default=2560, help="attitudes (default 2560)")
    p.add_argument("--resolution", type=int, default=64, help="image side in pixels (default 64)")
    p.add_argument("--chunk", type=int, default=128, help="attitudes per chunk (default 128)")
    p.add_argument("--write", nargs="?", const=True, default=False, metavar="PATH",
                   help=f"also write the report (default docs/{NAME})")
    a = p.parse_args(argv)
    try:
        workers = [int(x) for x in a.workers.split(",") if x.strip()]
    except ValueError:
        p.error(f"--workers {a.workers!r}: comma-separated integers")
    if not workers or min(workers) < 1:
        p.error("--workers: at least one count >= 1")
    main(workers, a.attitudes, a.resolution, a.chunk, a.write)


if __name__ == "__main__":
    _cli()
