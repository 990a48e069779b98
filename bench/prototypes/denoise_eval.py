"""How a denoiser prototype is judged on the cached bakes (bench.prototypes.denoise_data): RMSE against
the converged reference over interior texels, island-border texels, the 10% of texels with the
largest gradient of the reference, the seams' mean |difference|, and z = error / reported error.

    .venv/bin/python -m bench.prototypes.denoise_eval [--filters today] [--resolution 256 512]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.prototypes import denoise_data as data  # noqa: E402


def border(mask):
    """Covered texels with an uncovered 8-neighbour (or on the image's edge)."""
    p = np.pad(mask, 1)
    out = np.zeros_like(mask)
    h, w = mask.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= ~p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    return out & mask


def gradient(img, island):
    """|grad| of ``img`` per texel (central differences between texels of the same island, one-sided
    where only one side is on it; 0 where neither is)."""
    h, w = img.shape
    f = np.pad(np.asarray(img, np.float64), 1)
    isl = np.pad(island, 1, constant_values=-1)
    c = (slice(1, h + 1), slice(1, w + 1))
    own = isl[c]
    out = np.zeros((h, w))
    for axis in (0, 1):
        lo = (slice(0, h), slice(1, w + 1)) if axis == 0 else (slice(1, h + 1), slice(0, w))
        hi = (slice(2, h + 2), slice(1, w + 1)) if axis == 0 else (slice(1, h + 1), slice(2, w + 2))
        a, b = isl[lo] == own, isl[hi] == own
        d = np.where(a & b, (f[hi] - f[lo]) / 2, np.where(b, f[hi] - f[c], np.where(a, f[c] - f[lo], 0.0)))
        out += d * d
    return np.sqrt(out)


def high_gradient(ref, island, sel, share=0.1):
    """The ``share`` of the texels of ``sel`` with the largest reference gradient."""
    g = gradient(ref, island)
    cut = np.quantile(g[sel], 1 - share)
    return sel & (g >= cut)


def metrics(ao, se, ref, guide, mask=None):
    """RMSE (interior, border, high gradient), seams' mean |difference|, z sd against the reference."""
    from bench.harness.common import erode

    mask = ref["mask"] if mask is None else mask
    inner = erode(mask)
    edge = border(mask)
    steep = high_gradient(ref["ao"], guide.island, mask)
    e = np.asarray(ao, np.float64) - ref["ao"]
    out = {"rmse": float(np.sqrt(np.mean(e[inner] ** 2))), "border": float(np.sqrt(np.mean(e[edge] ** 2))),
           "steep": float(np.sqrt(np.mean(e[steep] ** 2))), "bias_border": float(e[edge].mean())}
    a, b = guide.links[:, 0], guide.links[:, 1]
    keep = mask.reshape(-1)[a] & mask.reshape(-1)[b]
    a, b = a[keep], b[keep]
    if len(a):
        f = np.asarray(ao, np.float64).reshape(-1)
        out["seams"] = float(np.mean(np.abs(f[a] - f[b])))
    if se is not None:
        s = np.sqrt(np.asarray(se, np.float64) ** 2 + ref["stderr"].astype(np.float64) ** 2)
        sel = mask & (np.asarray(se) > 0)
        z = e[sel] / s[sel]
        out["z_sd"] = float(z.std())
        out["z_over_4"] = float(np.mean(np.abs(z) > 4))
        zb = e[sel & edge] / s[sel & edge]
        out["z_sd_border"] = float(zb.std())
    return out


def today(ao, se, mask, guide):
    from core.post import denoise as D

    out, err, _ = D.denoise(ao, se, mask, guide, shapes=())
    return out, err


def _core(**kw):
    def f(ao, se, mask, guide):
        from core.post import denoise as D

        out, err, info = D.denoise(ao, se, mask, guide, **kw)
        print("choice", np.bincount(info.choice[mask], minlength=1 + len(info.bandwidths) + len(info.shapes)))
        return out, err
    return f


FILTERS = {"raw": lambda ao, se, mask, guide: (ao, se), "today": today, "core": _core(),
           "core25": _core(bandwidths=(2.5,)), "core20": _core(bandwidths=(2.0,))}


def run(filters, resolutions, scenes, samples=16, seed=1, cache=Path("/var/tmp/denoise-cache")):
    rows = []
    for res in resolutions:
        for name in scenes:
            g = data.guide(cache, name, res)
            ref = data.reference(cache, name, res)
            b = data.bake(cache, name, res, samples, seed)
            for fname in filters:
                f = FILTERS[fname]
                c = time.process_time()
                ao, se = f(b["ao"], b["stderr"], b["mask"], g)
                cpu = time.process_time() - c
                m = metrics(ao, se, ref, g)
                rows.append(dict(scene=name, res=res, filter=fname, cpu=cpu, **m))
                print(fmt(rows[-1]), flush=True)
    return rows


def fmt(r):
    keys = ("rmse", "border", "steep", "seams", "bias_border", "z_sd", "z_sd_border", "cpu")
    return f"{r['scene']:8s} {r['res']:4d} {r['filter']:14s} " + " ".join(
        f"{k} {r[k]:.4f}" for k in keys if k in r)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--filters", nargs="+", default=["raw", "today"])
    ap.add_argument("--resolution", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--scenes", nargs="+", default=list(data.SCENES))
    ap.add_argument("--samples", type=int, default=16)
    a = ap.parse_args(argv)
    run(a.filters, a.resolution, a.scenes, a.samples)



def _ms(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.multiscale import multiscale

        return multiscale(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"ms4": _ms(levels=4), "ms3": _ms(levels=3), "ms5": _ms(levels=5)})


def _oidn(kind):
    def f(ao, se, mask, guide):
        from bench.sections.denoise import oidn_filters
        from core.geometry.margin import dilate

        padded = np.asarray(ao, np.float32).copy()
        dilate(padded, mask, 16, out=padded)
        return oidn_filters()[0][kind](padded, None), None
    return f


FILTERS.update({"rtl": _oidn("OIDN RTLightmap"), "rt": _oidn("OIDN RT")})


def _bf(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.boxfit import boxfit_denoise

        return boxfit_denoise(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"box1": _bf(order=1), "box0": _bf(order=0)})


def _lep(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.boxfit import boxfit_lepski

        return boxfit_lepski(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"lep2": _lep(kappa=2.0), "lep1.5": _lep(kappa=1.5), "lep3": _lep(kappa=3.0),
                "lep2nofine": _lep(kappa=2.0, fine=False)})


def _sure(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.sure import sure_denoise

        return sure_denoise(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"sure4": _sure(rho=4), "sure8": _sure(rho=8), "sure4fine": _sure(rho=4, radii=()),
                "sure2": _sure(rho=2)})


def _pb(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.boxfit import pilot_bias_denoise

        return pilot_bias_denoise(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"pb": _pb(), "pb1": _pb(rho_scale=1.0), "pbmean": _pb(smooth_what="mean"),
                "pbnd": _pb(debias=False), "pbrr": _pb(rho_scale=1.0, report_raw=True),
                "pbit2": _pb(rho_scale=1.0, iterations=2), "pbd05": _pb(rho_scale=1.0, debias_scale=0.5),
                "pbfine": _pb(rho_scale=1.0, debias_scale=0.5, pilot="fine"),
                "pbds": _pb(rho_scale=1.0, debias_scale=0.5, with_ds=True),
                "pb2": _pb(rho_scale=1.0, debias_scale=0.5, radii=(2, 4, 8, 16)),
                "pbb": _pb(rho_scale=1.0, debias_scale=0.5, add_pilot_bias=True),
                "pbb1": _pb(rho_scale=1.0, debias_scale=1.0, add_pilot_bias=True),
                "pbbrr": _pb(rho_scale=1.0, add_pilot_bias=True, report_raw=True),
                "rect": _pb(rho_scale=1.0, debias_scale=0.5, radii=(3, 6, 12, (1, 6), (6, 1), (2, 12), (12, 2))),
                "rect2": _pb(rho_scale=1.0, debias_scale=0.5, radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2),
                                                                       (3, 12), (12, 3), (4, 24), (24, 4))),
                "rect2b": _pb(rho_scale=1.0, debias_scale=0.5, add_pilot_bias=True,
                              radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3), (4, 24), (24, 4))),
                "rect3": _pb(rho_scale=1.0, debias_scale=0.5, radii=(2, 3, 6, 12, 24, (1, 3), (3, 1), (1, 6), (6, 1), (2, 12),
                                                                       (12, 2), (3, 12), (12, 3), (4, 24), (24, 4))),
                "rect2it": _pb(rho_scale=1.0, debias_scale=0.5, iterations=2, radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12),
                                                                                   (12, 2), (3, 12), (12, 3), (4, 24), (24, 4))),
                "rect2r15": _pb(rho_scale=1.5, debias_scale=0.5, radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2),
                                                                         (3, 12), (12, 3), (4, 24), (24, 4))),
                **{f"rect2s{sp}": _pb(rho_scale=1.0, debias_scale=0.5, spread=sp,
                                      radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3), (4, 24),
                                             (24, 4))) for sp in (0.001, 0.003, 0.01, 0.03)},
                "v2": _pb(rho_scale=1.0, debias_scale=0.5, spread=0.003, iterations=2,
                          radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3), (4, 24), (24, 4))),
                "v2one": _pb(rho_scale=1.0, debias_scale=0.5, spread=0.003, iterations=1,
                             radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3), (4, 24), (24, 4))),
                **{f"v2f{i}": _pb(rho_scale=1.0, debias_scale=0.5, spread=0.003, iterations=1, fine_bandwidths=fb,
                                  fine_radius=fr, radii=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3),
                                                         (4, 24), (24, 4)))
                   for i, (fb, fr) in enumerate((((1.25, 2.5), 3), ((1.0, 1.8), 2), ((1.5,), 2), ((1.25,), 2), ((2.0,), 3),
                                                   ((2.5,), 3), ((1.25, 2.5), 2)))},
                **{f"shp{k}": _pb(rho_scale=1.0, debias_scale=0.5, spread=0.003, fine_bandwidths=(2.5,), radii=r)
                   for k, r in dict(A=(3, 6, 12, 24, (1, 6), (6, 1), (2, 12), (12, 2), (3, 12), (12, 3), (4, 24), (24, 4)),
                                    B=(6, 12, (2, 12), (12, 2), (4, 24), (24, 4)), C=(4, 12, (2, 12), (12, 2)),
                                    D=(6, 18, (2, 12), (12, 2)), E=(4, 8, 16, (2, 8), (8, 2), (3, 16), (16, 3))).items()},
                **{f"at{L}": _pb(rho_scale=1.0, debias_scale=0.5, spread=0.003, fine=L,
                                 radii=(6, 12, (2, 12), (12, 2), (4, 24), (24, 4))) for L in (1, 2)},
                "rectb": _pb(rho_scale=1.0, debias_scale=0.5, add_pilot_bias=True,
                             radii=(3, 6, 12, (1, 6), (6, 1), (2, 12), (12, 2)))})


def _tiled(**kw):
    def f(ao, se, mask, guide):
        from bench.prototypes.atrous import tiled_denoise

        return tiled_denoise(ao, se, mask, guide, verbose=True, **kw)
    return f


FILTERS.update({"t3": _tiled(), "t3f": _tiled(with_fine=True), "t3d1": _tiled(debias_scale=1.0),
                "t3r1": _tiled(rho_scale=1.0), "t3bd": _tiled(beta_decay=3.0)})


if __name__ == "__main__":
    main()
