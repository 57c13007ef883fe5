"""Cost of a likelihood evaluation with roughness free for a single-term material (notebook
04's problem: a bare 1U box of Beckmann metal, 48 px, co/cross, 2e4 counts), against the
attitude alone, in one run: ``alpha_step="auto"`` (the default; the material, 36 ms to
build, is rebuilt at every alpha and rendered once) and nodes 5% apart (four renders per
evaluation). 12 evaluations in a batch (an emcee step) and 6 one at a time (nlopt steps),
the median of 4 repeats after one warm-up; ratios to the attitude's cost.
Materials with the double or multiple term: ``benchmarks/bench_fit.py``.

``python benchmarks/bench_fit_single.py`` prints the table.
"""
import time, numpy as np, pprender
from scipy.spatial.transform import Rotation
from pprender import fit, models
def metal(alpha):
    return pprender.Material("beckmann", alpha=alpha, eta=1.38 + 10.2j, terms=["single"])
mesh = models.cubesat("1U", panels=None, antenna=False, detail=0)
lidar = pprender.Lidar(resolution=48, supersampling=2)
att = Rotation.from_rotvec([0.4, 0.3, 0.2]).as_matrix()[None]
base = pprender.Instrument(pulse_energy=1e-3, target_range=500e3, jitter=20e-12, background_rate=1e5, n_pulses=10**5, channels="co_cross_linear")
tr = pprender.render(pprender.Scene(mesh, metal(0.3)), pprender.Lidar(resolution=48, supersampling=2, polarization=base.channels.transmit), att, outputs=("profile",))
inst = base.scaled_to(2e4, tr); data = pprender.measure(tr, inst, seed=11)[0]
rng = np.random.default_rng(0)
kw = dict(lidar=lidar, fixed={"ry": 0.3, "rz": 0.2}, bounds={"rx": (-1.0, 1.0), "alpha": (0.05, 0.8)})
models_ = {"attitude (rx)": fit.ForwardModel(mesh, metal(0.3), inst, data.bin_edges, ("rx",), lidar=lidar, fixed={"ry": 0.3, "rz": 0.2}, bounds={"rx": (-1.0, 1.0)}),
           "rx + alpha, auto (exact)": fit.ForwardModel(mesh, metal(0.3), inst, data.bin_edges, ("rx", "alpha"), **kw),
           "rx + alpha, nodes 0.05": fit.ForwardModel(mesh, metal(0.3), inst, data.bin_edges, ("rx", "alpha"), alpha_step=0.05, **kw)}
res = {k: {"batch": [], "single": []} for k in models_}
for rep in range(5):
    for k, m in models_.items():
        pts = np.array([0.4, 0.3]) + 0.01 * rng.standard_normal((12, 2))
        if m.ndim == 1: pts = pts[:, :1]
        t0 = time.perf_counter(); m.log_likelihood(pts, data); res[k]["batch"].append((time.perf_counter() - t0) / 12)
        t0 = time.perf_counter()
        for p in pts[:6]: m.log_likelihood(p, data)
        res[k]["single"].append((time.perf_counter() - t0) / 6)
a = {s: np.median(res["attitude (rx)"][s][1:]) for s in ("batch", "single")}
for k in models_:
    b, s = np.median(res[k]["batch"][1:]), np.median(res[k]["single"][1:])
    print(f"{k:28s} batch {b*1e3:6.1f} ms ({b/a['batch']:.1f}x)   one at a time {s*1e3:6.1f} ms ({s/a['single']:.1f}x)")
