"""Orders 3+ of the path bank against the explicit surface at backscatter (0 and 30 deg)
and 15 deg off it: M00, depolarization index, M33/M00. Run from the repository root:

    python scripts/bank_orders3_backscatter.py ALPHA BANK_RAYS REF_RAYS   (e.g. 0.8 4e6 1e7)
"""
import sys, math, numpy as np
sys.path.insert(0, "scripts")
import compare_microsurface as cm
from bank_vs_surface import depol
from pprender import _core
alpha = float(sys.argv[1]); rays = int(float(sys.argv[2])); refrays = int(float(sys.argv[3]))
bank = _core.PathBank(alpha, rays, surfaces=64, seed=1)
for ename, eta in (("PEC", cm.PEC), ("Al", 0.2 + 3.4j)):
    t3 = bank.table(eta, orders=(3, 8))
    for th in (0.0, 30.0):
        wi = cm.direction(th); wos = [wi, cm.direction(th + 15.0)]
        r = cm.reference_run(wi, wos, alpha=alpha, eta=eta, rays=refrays, cone=0.1, seed=999 + int(th))
        m3 = cm.cone_average(lambda a, b: t3.eval(a, b, "sp"), wi, wos, 0.1, (2, 8))
        for j in range(2):
            per = r["mueller"][:, 2, j]; m00, se = cm.mean_se(per[:, 0, 0]); mean = per.mean(0)
            print(f"{ename} th {th} wo {j}: 3+ ref {m00:.4g}+-{se/m00:.1%} n={r['counts'][2, j]} bank/ref {m3[j][0,0]/m00:.3f} DI ref {depol(mean):.3f} bank {depol(m3[j]):.3f} M33 ref {mean[3,3]/mean[0,0]:+.3f} bank {m3[j][3,3]/m3[j][0,0]:+.3f}", flush=True)
