"""Whole return (all orders) at normal-incidence backscatter, coherent backscatter off:
the depolarization index and M00 of orders="seed" and orders="surface" against the explicit
surface (4e6 reference rays, cone 0.1, seed 555). Run from the repository root:

    python scripts/whole_return_depolarization.py [ALPHA]   (default 0.6)
"""
import sys, math, numpy as np
sys.path.insert(0, "scripts")
import compare_microsurface as cm
from bank_vs_surface import depol
import pprender
alpha = float(sys.argv[1]) if len(sys.argv) > 1 else 0.6
for ename, eta in (("PEC", cm.PEC), ("Al", 0.2 + 3.4j), ("glass", 1.5 + 0j)):
    wi = cm.direction(0.0); wos = [wi]
    r = cm.reference_run(wi, wos, alpha=alpha, eta=eta, rays=4_000_000, cone=0.1, seed=555)
    tot = r["mueller"][:, :, 0].sum(axis=1)  # (calls, 4, 4) all orders
    mean = tot.mean(0)
    dis = [depol(t) for t in tot]
    out = [f"{ename}: surface M00 {mean[0,0]:.4f} DI {depol(mean):.3f} (+- {np.std(dis, ddof=1)/math.sqrt(len(dis)):.3f})"]
    for orders in ("seed", "surface"):
        m = pprender.Material("beckmann", alpha=alpha, eta=eta, terms=("single", "double", "multiple"),
                              coherent_backscatter=False, orders=orders)
        mc = cm.cone_average(lambda a, b: pprender.brdf(m, a, b), wi, wos, 0.1, (2, 8))[0]
        out.append(f"{orders}: M00 {mc[0,0]:.4f} ({mc[0,0]/mean[0,0]:.3f}x) DI {depol(mc):.3f}")
    print("  ".join(out), flush=True)
