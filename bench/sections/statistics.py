"""Statistics of core.bake_ao on a scene whose AO is known exactly: convergence and bias per sample source.

The analytic scene (bench.harness.scene.lid_scene): the unit plane under a hovering square, exact texel AO
1 - F (Lambert's polygon form factor, integrated over each texel). For every source, RMSE over all
texels against the exact values at doubling sample counts, and the slope of log RMSE against log
samples (independent samples: -1/2; Owen-scrambled Sobol' nets do better on this piecewise-smooth
integrand); the mean error at the largest count with its standard error (no bias). No Blender.
"""

import numpy as np

from ..harness import mcao
from ..harness.common import log
from ..harness.scene import lid_scene, lid_truth

SOURCES = ("sobol", "halton", "stratified", "independent")


def _meshes():
    from core import Mesh

    pv, pq, puv, lv, lq = lid_scene()
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    plane = Mesh(pv, pq[0][tri], uvs=np.asarray(puv)[tri], name="plane")
    lid = Mesh(lv, lq[0][tri], name="lid")
    return plane, lid


def statistics(ctx):
    cfg = ctx.cfg
    res = cfg["stat_res"]
    plane, lid = _meshes()
    truth = lid_truth(res, res)
    out = {"scene": "unit plane under a square at height 0.3 (exact 1 - F per texel)", "resolution": res,
           "samples": list(cfg["stat_spp"]), "sources": {}}
    for source in SOURCES:
        rmse, seconds = [], []
        for spp in cfg["stat_spp"]:
            r = mcao.core_bake(plane, [lid], resolution=res, samples=spp, source=source, seed=17, threads=ctx.threads)
            err = r.ao.astype(np.float64) - truth
            rmse.append(float(np.sqrt(np.mean(err * err))))
            seconds.append(r.seconds)
        slope = float(np.polyfit(np.log(cfg["stat_spp"]), np.log(rmse), 1)[0])
        mean = float(err.mean())
        se = float(np.sqrt(np.mean(r.stderr.astype(np.float64) ** 2) / err.size))
        out["sources"][source] = {"rmse": rmse, "seconds": seconds, "slope": slope, "mean_error": mean,
                                  "mean_error_se_iid": se}
        log(f"statistics {source}: RMSE {rmse[0]:.4f} @ {cfg['stat_spp'][0]} -> {rmse[-1]:.5f} @ "
            f"{cfg['stat_spp'][-1]} spp, slope {slope:+.2f}; mean error {mean:+.6f}", ctx.clock)
    return out
