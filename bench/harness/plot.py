"""Figures of a benchmark run: ``python -m bench.harness.plot [bench/results/latest.json]`` -> docs/bench_*.png."""

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def equal_error(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ee = data["results"]["equal_error"]
    fig, ax = plt.subplots(figsize=(7.5, 5), dpi=110)
    styles = {"cycles": dict(color="black", lw=2.2, marker="s"), "sobol": dict(color="tab:blue", marker="o"),
              "halton": dict(color="tab:green", marker="^"), "stratified": dict(color="tab:orange", marker="v"),
              "independent": dict(color="tab:red", marker="x")}
    for name, pts in ee["series"].items():
        if not pts:
            continue
        base = name.split("+")[0]
        st = dict(styles.get(base, {}))
        if name.endswith("+adaptive"):
            st.update(ls="--", alpha=0.7)
        label = "Cycles AO bake" if name == "cycles" else f"mc_ao {name}"
        ax.plot([p["seconds"] for p in pts], [p["rmse"] for p in pts], label=label, **st)
    c = ee.get("cycles_at_128")
    if c:
        ax.axhline(c["rmse"], color="grey", lw=0.8, ls=":")
        ax.annotate("Cycles @128 spp", (c["seconds"], c["rmse"]), textcoords="offset points", xytext=(6, 6), fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall seconds (2 threads)")
    ax.set_ylabel(f"RMSE vs {ee['reference']['samples']}-spp reference")
    m = data["machine"]
    ax.set_title(f"Equal error, Suzanne {ee['resolution']}x{ee['resolution']} ({m['cores']} cores, {data['started'][:10]})",
                 fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    src = Path(argv[0]) if argv else Path(__file__).resolve().parents[1] / "results" / "latest.json"
    data = json.loads(src.read_text())
    if "equal_error" in data["results"]:
        print(equal_error(data, DOCS / "bench_equal_error.png"))


if __name__ == "__main__":
    main()
