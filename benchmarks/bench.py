"""BRDF evaluation throughput: pprender next to Mitsuba 3's vectorized ``eval``.

Run ``python benchmarks/bench.py`` (``--write`` also writes ``docs/benchmark.md``), or call
:func:`main` (``bench.main(n=1_000_000)`` with ``benchmarks/`` on ``sys.path``).

What is measured, in one process and interleaved round by round:

* ``n`` random direction pairs (seeded), both uniform in solid angle over the upper
  hemisphere; float64 for pprender, the same values rounded to float32 for Mitsuba.
* pprender ``brdf(material, wi, wo, frame="mitsuba")`` for (a) the default single +
  multiple APS material with table masking, ``Material("beckmann", alpha=0.3,
  eta=0.2+3.4j)``, and (b) the single-term Smith material that matches Mitsuba's
  ``roughconductor`` (``shadowing="smith", smith_g1="walter", terms=("single",)``).
  NumPy ``(n, 3)`` float64 in, ``(n, 4, 4)`` float64 out; rayon uses every core.
* Mitsuba 3 ``roughconductor`` (Beckmann, alpha 0.3, same eta and k) ``bsdf.eval`` in
  ``llvm_ad_mono_polarized`` (float32, drjit's LLVM backend, its own thread pool using
  every core): "numpy in/out" builds the inputs from NumPy float32 arrays and converts the
  ``(4, 4, 1, n)`` result back to NumPy (the like-for-like comparison, used for the
  ratio); "kernel only" evaluates on inputs already in drjit arrays, without the copy out.
* One-off costs (material construction, the first call: rayon pool start-up, page
  faults, Mitsuba's import and JIT compilation or kernel-cache load) are timed separately
  and excluded from the throughput. Each measurement is repeated ``repeats`` times; best
  and median are reported, evals/s from the best.
* ``--profile`` (on by default) adds where pprender's time goes: throughput against n,
  the cost of the binding alone (directions on the horizon, which return the zero matrix
  without evaluating the model), the Python wrapper's share, and 1-thread against
  all-thread runs (a subprocess with ``RAYON_NUM_THREADS=1``).
"""

from __future__ import annotations

import argparse
import glob
import importlib.metadata
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

import pprender
from pprender import _core

SEED = 12345
ALPHA = 0.3
ETA = 0.2 + 3.4j
TARGET_RATIO = 3.0


# --------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------


def uniform_hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` unit vectors uniform in solid angle over z >= 0 (z uniform in [0, 1))."""
    z = rng.random(n)
    r = np.sqrt(1.0 - z * z)
    phi = 2.0 * np.pi * rng.random(n)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def direction_pairs(n: int, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return uniform_hemisphere(rng, n), uniform_hemisphere(rng, n)


def aps_material() -> pprender.Material:
    return pprender.Material("beckmann", alpha=ALPHA, eta=ETA)


def smith_material() -> pprender.Material:
    return pprender.Material(
        "beckmann", alpha=ALPHA, eta=ETA, shadowing="smith", correlation="none", smith_g1="walter", terms=("single",)
    )


def timed(f: Callable[[], Any]) -> float:
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0


@dataclass
class Timing:
    label: str
    n: int
    times: list[float] = field(default_factory=list)
    one_off: dict[str, float] = field(default_factory=dict)
    note: str = ""

    @property
    def best(self) -> float:
        return min(self.times)

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    @property
    def rate(self) -> float:
        return self.n / self.best


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def load_average() -> str:
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "n/a"


def threads_available() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------


class MitsubaBench:
    """Mitsuba's roughconductor in llvm_ad_mono_polarized on the same direction pairs."""

    def __init__(self, wi: np.ndarray, wo: np.ndarray):
        t0 = time.perf_counter()
        self._prepare_llvm()
        import drjit as dr
        import mitsuba as mi

        mi.set_variant("llvm_ad_mono_polarized")
        self.t_import = time.perf_counter() - t0
        self.dr, self.mi = dr, mi
        self.version = f"mitsuba {getattr(mi, '__version__', '?')}, drjit {getattr(dr, '__version__', '?')}"
        self.threads = int(dr.thread_count()) if hasattr(dr, "thread_count") else -1
        t0 = time.perf_counter()
        self.bsdf = mi.load_dict(
            {"type": "roughconductor", "distribution": "beckmann", "alpha": ALPHA, "eta": ETA.real, "k": ETA.imag}
        )
        self.t_load = time.perf_counter() - t0
        self.ctx = mi.BSDFContext()
        self.n = len(wi)
        # Structure-of-arrays float32 inputs, Mitsuba's native layout (prepared once).
        self.wi_soa = [np.ascontiguousarray(wi[:, k], dtype=np.float32) for k in range(3)]
        self.wo_soa = [np.ascontiguousarray(wo[:, k], dtype=np.float32) for k in range(3)]
        self._si: Any = None
        self._wo_arg: Any = None

    @staticmethod
    def _prepare_llvm() -> None:
        """drjit >= 1.5 aborts the process with LLVM 15/16: point it at LLVM >= 17 if one is
        installed, otherwise refuse (mitsuba 3.9.0 / drjit 1.4.0 work with LLVM 15)."""
        try:
            version = importlib.metadata.version("drjit")
        except importlib.metadata.PackageNotFoundError as e:
            raise ImportError("drjit is not installed") from e
        major_minor = tuple(int("".join(c for c in p if c.isdigit()) or 0) for p in version.split(".")[:2])
        if major_minor < (1, 5) or os.environ.get("DRJIT_LIBLLVM_PATH"):
            return
        found = sorted(
            glob.glob("/usr/lib/llvm-1[7-9]/lib/libLLVM*.so*") + glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM*1[7-9]*.so*")
        )
        if not found:
            raise ImportError(f"drjit {version} needs LLVM >= 17 (set DRJIT_LIBLLVM_PATH) or pin drjit==1.4.0")
        os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]

    def _si_from_numpy(self):
        dr, mi = self.dr, self.mi
        si = dr.zeros(mi.SurfaceInteraction3f, self.n)
        si.wi = mi.Vector3f(*self.wo_soa)  # Mitsuba's si.wi = our wo (toward the sensor)
        return si

    def eval_numpy(self) -> np.ndarray:
        """NumPy float32 in, NumPy (4, 4, 1, n) float32 out."""
        si = self._si_from_numpy()
        value = self.bsdf.eval(self.ctx, si, self.mi.Vector3f(*self.wi_soa))  # wo = our wi
        return np.asarray(value)

    def prepare_kernel_only(self) -> None:
        dr = self.dr
        self._si = self._si_from_numpy()
        self._wo_arg = self.mi.Vector3f(*self.wi_soa)
        dr.eval(self._si, self._wo_arg)
        dr.sync_thread()

    def eval_kernel_only(self) -> None:
        dr = self.dr
        value = self.bsdf.eval(self.ctx, self._si, self._wo_arg)
        dr.eval(value)
        dr.sync_thread()

    def thread_scaling(self, repeats: int) -> dict[str, float] | None:
        """Best kernel-only time with 1 drjit thread and with the default count."""
        dr = self.dr
        if not hasattr(dr, "set_thread_count"):
            return None
        default = int(dr.thread_count())
        out = {}
        try:
            for count in (1, default):
                dr.set_thread_count(count)
                self.eval_kernel_only()
                out[str(count)] = min(timed(self.eval_kernel_only) for _ in range(repeats))
        finally:
            dr.set_thread_count(default)
        return out


# --------------------------------------------------------------------------------------
# Profile helpers
# --------------------------------------------------------------------------------------

_SUBPROCESS_SNIPPET = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[3])
import bench
from pprender import _core
n, repeats = int(sys.argv[1]), int(sys.argv[2])
wi, wo = bench.direction_pairs(n)
out = {}
for name, make in (("aps", bench.aps_material), ("smith", bench.smith_material)):
    m = make()
    _core.brdf(m, wi, wo, "mitsuba")
    out[name] = min(bench.timed(lambda: _core.brdf(m, wi, wo, "mitsuba")) for _ in range(repeats))
print(json.dumps(out))
"""


def _threads_subprocess(n: int, repeats: int, threads: int) -> dict[str, float] | None:
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    try:
        r = subprocess.run(
            [sys.executable, "-c", _SUBPROCESS_SNIPPET, str(n), str(repeats), str(Path(__file__).parent)],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=True,
        )
        return json.loads(r.stdout.strip().splitlines()[-1])
    except (subprocess.SubprocessError, ValueError, IndexError, OSError):
        return None


def profile(materials: dict[str, pprender.Material], n: int, repeats: int,
            mits: MitsubaBench | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {}
    # 1. Throughput against n (per-element cost), all threads.
    sizes = sorted({s for s in (1_000, 10_000, 100_000, n) if s <= n})
    per_n: dict[int, dict[str, float]] = {}
    for s in sizes:
        wi, wo = direction_pairs(s, seed=SEED + 1)
        reps = repeats if s >= 100_000 else max(repeats, 20)
        row = {}
        for name, m in materials.items():
            _core.brdf(m, wi, wo, "mitsuba")
            row[name] = min(timed(lambda: _core.brdf(m, wi, wo, "mitsuba")) for _ in range(reps)) / s
        per_n[s] = row
    out["per_n"] = per_n
    # 2. The binding alone: directions on the horizon give the zero matrix without
    #    evaluating the model (validation, allocation, output conversion remain).
    wz = np.tile([1.0, 0.0, 0.0], (n, 1))
    m = materials["smith"]
    _core.brdf(m, wz, wz, "mitsuba")
    out["glue"] = min(timed(lambda: _core.brdf(m, wz, wz, "mitsuba")) for _ in range(repeats)) / n
    # Floors: NumPy allocating and writing a fresh (n, 4, 4) float64 array (page faults
    # included, as for every new result array), and refilling a preallocated one.
    out["numpy_floor"] = min(timed(lambda: np.ones((n, 4, 4))) for _ in range(repeats)) / n
    buf = np.empty((n, 4, 4))
    out["numpy_floor_prealloc"] = min(timed(lambda: buf.fill(1.0)) for _ in range(repeats)) / n
    del buf
    # 3. The Python wrapper (validation, broadcasting, reshape) against the raw binding.
    wi, wo = direction_pairs(n)
    py = min(timed(lambda: pprender.brdf(m, wi, wo, frame="mitsuba")) for _ in range(repeats))
    raw = min(timed(lambda: _core.brdf(m, wi, wo, "mitsuba")) for _ in range(repeats))
    out["wrapper"] = {"python": py / n, "raw": raw / n}
    # 4. Thread scaling (separate processes: rayon's pool size is fixed at start-up).
    t1 = _threads_subprocess(n, max(2, repeats // 2), 1)
    tall = _threads_subprocess(n, max(2, repeats // 2), threads_available())
    out["threads"] = {"1": t1, str(threads_available()): tall}
    # 5. Mitsuba on one drjit thread (per-core comparison with pprender on one thread).
    if mits is not None:
        out["mitsuba_threads"] = mits.thread_scaling(repeats)
    return out


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------


def _fmt_rate(r: float) -> str:
    return f"{r / 1e6:.2f} M/s"


def _fmt_ms(t: float) -> str:
    return f"{t * 1e3:.0f} ms" if t >= 0.01 else f"{t * 1e3:.1f} ms"


def render(results: list[Timing], reference: Timing | None, kernel_only: Timing | None, info: dict[str, Any],
           prof: dict[str, Any] | None) -> str:
    n = results[0].n
    lines = ["# BRDF evaluation throughput", ""]
    lines.append(
        f"`python benchmarks/bench.py` ({n:,} random direction pairs, uniform in solid angle, seed {SEED}; "
        f"best and median of {info['repeats']} runs, measured in the same process, interleaved; "
        "one-off costs excluded and listed below). Mueller BRDF in the Mitsuba frame, "
        "`frame=\"mitsuba\"`."
    )
    lines.append("")
    lines.append(f"- Machine: {info['cpu']}, {info['threads']} threads available "
                 f"(pprender/rayon: {info['rayon_threads']}, drjit: {info['drjit_threads']}); "
                 f"load average at start {info['load_start']}, at end {info['load_end']}.")
    lines.append(f"- Software: pprender {pprender.__version__} (float64), {info['mitsuba']} "
                 f"(`llvm_ad_mono_polarized`, float32), numpy {np.__version__}, Python {platform.python_version()}.")
    lines.append("")
    lines.append("| implementation | evals/s (best) | time per 1e6 (best) | time per 1e6 (median) | ratio to Mitsuba |")
    lines.append("| --- | ---: | ---: | ---: | ---: |")

    def row(t: Timing) -> str:
        ratio = f"{t.rate / reference.rate:.2f}x" if reference is not None else "n/a"
        return (f"| {t.label} | {_fmt_rate(t.rate)} | {_fmt_ms(t.best * 1e6 / t.n)} | "
                f"{_fmt_ms(t.median * 1e6 / t.n)} | {ratio} |")

    for t in results:
        lines.append(row(t))
    if reference is not None:
        lines.append(row(reference))
    if kernel_only is not None:
        lines.append(row(kernel_only))
    lines.append("")
    lines.append("Ratio: evals/s divided by Mitsuba's (NumPy in/out) evals/s, both best-of-runs.")
    if reference is None:
        lines.append(f"Mitsuba was not measured: {info.get('mitsuba_error', 'unavailable')}.")
    lines.append("")
    lines.append("One-off costs (excluded from the throughput):")
    lines.append("")
    for t in results + [x for x in (reference,) if x is not None]:
        parts = ", ".join(f"{k} {_fmt_ms(v)}" for k, v in t.one_off.items())
        lines.append(f"- {t.label}: {parts}.")
    lines.append("")
    if reference is not None:
        aps = results[0]
        ratio = aps.rate / reference.rate
        verdict = "meets" if ratio >= TARGET_RATIO else "does NOT meet"
        lines.append(
            f"Target: pprender single+multiple APS >= {TARGET_RATIO:g}x Mitsuba's vectorized eval. "
            f"Measured {ratio:.2f}x: {verdict} the target."
        )
        lines.append("")
    if prof is not None:
        lines += render_profile(prof, results, reference)
    return "\n".join(lines) + "\n"


def render_profile(prof: dict[str, Any], results: list[Timing], reference: Timing | None) -> list[str]:
    lines = ["## Where pprender's time goes", ""]
    lines.append("Per-element cost (ns) of the raw binding `_core.brdf` against n (all threads, best of runs):")
    lines.append("")
    lines.append("| n | APS single+multiple | Smith single |")
    lines.append("| ---: | ---: | ---: |")
    for s, row in prof["per_n"].items():
        lines.append(f"| {s:,} | {row['aps'] * 1e9:.0f} | {row['smith'] * 1e9:.0f} |")
    lines.append("")
    n = results[0].n
    glue = prof["glue"]
    floor = prof["numpy_floor"]
    aps_t = results[0].best / n
    smith_t = results[1].best / n
    lines.append(
        f"- Binding alone (directions on the horizon: validation, allocation, result conversion, no model "
        f"evaluation): {glue * 1e9:.0f} ns per element, i.e. {100 * glue / aps_t:.0f}% of the APS time and "
        f"{100 * glue / smith_t:.0f}% of the Smith time at n = {n:,}. NumPy allocating and filling the same "
        f"(n, 4, 4) float64 output takes {floor * 1e9:.0f} ns per element."
    )
    w = prof["wrapper"]
    lines.append(
        f"- Python wrapper (`pprender.brdf`: asarray, broadcasting, reshape) against `_core.brdf`: "
        f"{w['python'] * 1e9:.0f} against {w['raw'] * 1e9:.0f} ns per element "
        f"({100 * (w['python'] - w['raw']) / w['raw']:+.0f}%)."
    )
    th = prof["threads"]
    keys = list(th)
    if all(th[k] is not None for k in keys) and len(keys) == 2 and keys[0] != keys[1]:
        one, many = th[keys[0]], th[keys[1]]
        lines.append(
            f"- Threads (separate processes, RAYON_NUM_THREADS): APS {one['aps'] * 1e3:.0f} ms with 1 thread, "
            f"{many['aps'] * 1e3:.0f} ms with {keys[1]} (speed-up {one['aps'] / many['aps']:.2f}x); Smith "
            f"{one['smith'] * 1e3:.0f} ms against {many['smith'] * 1e3:.0f} ms "
            f"({one['smith'] / many['smith']:.2f}x)."
        )
        mt = prof.get("mitsuba_threads")
        if mt and "1" in mt:
            other = [k for k in mt if k != "1"]
            extra = f", {mt[other[0]] * 1e3:.1f} ms with {other[0]}" if other else ""
            lines.append(
                f"- Per core: with one thread each, pprender Smith takes {one['smith'] * 1e9 / n:.0f} ns per element "
                f"and Mitsuba's kernel {mt['1'] * 1e9 / n:.1f} ns ({mt['1'] * 1e3:.1f} ms per {n:,}{extra}): "
                f"a factor {one['smith'] / mt['1']:.1f} per core, float64 scalar code against float32 "
                "SIMD (drjit vectorizes across elements)."
            )
    else:
        lines.append("- Thread scaling: not measured (single core, or the subprocess failed).")
    pre = prof.get("numpy_floor_prealloc")
    if reference is not None:
        need = reference.best / TARGET_RATIO
        lines.append(
            f"- Feasibility of the {TARGET_RATIO:g}x target: it needs {need * 1e3:.1f} ms per {reference.n:,} "
            f"evaluations including the result; a fresh (n, 4, 4) float64 NumPy array alone takes "
            f"{floor * n * 1e3:.1f} ms to allocate and write here"
            + (f" ({pre * n * 1e3:.1f} ms to refill a preallocated one)" if pre is not None else "")
            + "."
        )
    if reference is not None:
        mi_t = reference.best / reference.n
        lines.append(
            f"- For scale: Mitsuba's whole eval, NumPy in/out, costs {mi_t * 1e9:.0f} ns per element here, "
            f"{'less' if mi_t < glue else 'more'} than pprender's binding alone ({glue * 1e9:.0f} ns)."
        )
    lines.append("")
    return lines


# --------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------


def main(n: int = 1_000_000, repeats: int = 5, write: bool | str | os.PathLike[str] = False,
         with_profile: bool = True, with_mitsuba: bool = True, quiet: bool = False) -> str:
    """Run the benchmark, print the markdown report and return it. ``write=True`` writes
    ``docs/benchmark.md`` of the source tree (or of the working directory); a path writes
    there."""
    if n < 1 or repeats < 1:
        raise ValueError("n and repeats must be positive")
    info: dict[str, Any] = {
        "cpu": cpu_model(),
        "threads": threads_available(),
        "rayon_threads": os.environ.get("RAYON_NUM_THREADS", str(threads_available())),
        "load_start": load_average(),
        "repeats": repeats,
        "mitsuba": "mitsuba n/a",
        "drjit_threads": "n/a",
    }
    wi, wo = direction_pairs(n)

    # pprender: one-off material construction and first call.
    timings: list[Timing] = []
    mats: dict[str, pprender.Material] = {}
    for key, label, make in (
        ("aps", "pprender single+multiple APS (table masking)", aps_material),
        ("smith", "pprender single Smith (Mitsuba-equivalent)", smith_material),
    ):
        t0 = time.perf_counter()
        m = make()
        t_build = time.perf_counter() - t0
        t_first = timed(lambda: pprender.brdf(m, wi, wo, frame="mitsuba"))
        mats[key] = m
        timings.append(Timing(label, n, one_off={"material build": t_build, "first call": t_first}))

    mits: MitsubaBench | None = None
    reference: Timing | None = None
    kernel_only: Timing | None = None
    if with_mitsuba:
        try:
            mits = MitsubaBench(wi, wo)
            t_first = timed(mits.eval_numpy)
            mits.prepare_kernel_only()
            t_first_k = timed(mits.eval_kernel_only)
            info["mitsuba"] = mits.version
            info["drjit_threads"] = mits.threads
            reference = Timing("Mitsuba 3 roughconductor eval (NumPy in/out)", n, one_off={
                "import + set_variant": mits.t_import, "load_dict": mits.t_load,
                "first call (JIT compile or kernel-cache load)": t_first,
                "first kernel-only call": t_first_k})
            kernel_only = Timing("Mitsuba 3 eval, kernel only (inputs already in drjit, no copy out)", n)
        except Exception as e:  # Mitsuba missing or broken: report pprender alone
            info["mitsuba_error"] = repr(e)
            mits = None

    for _ in range(repeats):  # interleaved rounds
        for t, key in zip(timings, ("aps", "smith")):
            m = mats[key]
            t.times.append(timed(lambda: pprender.brdf(m, wi, wo, frame="mitsuba")))
        if mits is not None and reference is not None and kernel_only is not None:
            reference.times.append(timed(mits.eval_numpy))
            kernel_only.times.append(timed(mits.eval_kernel_only))

    prof = profile(mats, n, repeats, mits) if with_profile else None
    info["load_end"] = load_average()
    report = render(timings, reference, kernel_only, info, prof)
    return emit_report(report, write, "benchmark.md", quiet)


def emit_report(report: str, write: bool | str | os.PathLike[str], name: str, quiet: bool) -> str:
    """Print a benchmark report and, when ``write`` is true (or a path), store it: by
    default as ``docs/<name>`` of the source checkout (or of the working directory)."""
    if not quiet:
        print(report, end="")
    if write:
        path = default_output(name) if write is True else Path(write)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(report)
        if not quiet:
            print(f"(written to {path})")
    return report


def default_output(name: str) -> Path:
    root = Path(__file__).resolve().parents[1]
    if (root / "Cargo.toml").exists() and (root / "pyproject.toml").exists():
        return root / "docs" / name
    return Path.cwd() / "docs" / name


def _cli(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python benchmarks/bench.py", description=__doc__.splitlines()[0])
    p.add_argument("-n", "--n", type=int, default=1_000_000, help="direction pairs (default 1e6)")
    p.add_argument("-r", "--repeats", type=int, default=5, help="timed repetitions (default 5)")
    p.add_argument("--write", nargs="?", const=True, default=False, metavar="PATH",
                   help="also write the report (default docs/benchmark.md)")
    p.add_argument("--no-profile", action="store_true", help="skip the where-does-time-go section")
    p.add_argument("--no-mitsuba", action="store_true", help="measure pprender only")
    a = p.parse_args(argv)
    main(n=a.n, repeats=a.repeats, write=a.write, with_profile=not a.no_profile, with_mitsuba=not a.no_mitsuba)


if __name__ == "__main__":
    _cli()
