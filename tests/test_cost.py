"""core.execution.cost: the estimate shown before a bake, against the bench's recorded bakes (no timing here:
the figures are the bench's, bench/results/latest.json)."""

import json
from pathlib import Path

import numpy as np
import pytest

from core import Mesh, cost

LATEST = Path(__file__).resolve().parents[1] / "bench" / "results" / "latest.json"


def bench():
    return json.loads(LATEST.read_text())["results"]


def rows():
    """(what, covered texels, samples, triangles, threads, measured seconds) of the bench's core bakes."""
    r = bench()
    suzanne = 3962  # Suzanne, the ground and the blocks
    out = [("resolution", x["texels"], x["rays"] // x["texels"], suzanne, x["threads"], x["seconds"])
           for x in r["resolution"]["rows"] + r["resolution"]["one_sample"]]
    out += [("triangles", x["texels"], x["rays"] // x["texels"], x["triangles"], x["threads"], x["seconds"])
            for x in r["triangles"]["rows"]]
    out += [("equal samples", x["mc_texels"], x["samples"], suzanne, x["threads"], x["mc_core_s"])
            for x in r["equal_samples"]["rows"]]
    d = r["dense"]
    out.append(("dense", d["resolution"] ** 2 * 0.95, d["samples"], d["triangles"], d["threads"], d["mc_core_s"]))
    return out


@pytest.mark.parametrize("what, texels, samples, triangles, threads, seconds", rows())
def test_the_time_estimate_is_within_2x_of_the_bench(what, texels, samples, triangles, threads, seconds):
    est = cost.estimate(texels, samples, triangles, threads=threads)
    assert 0.5 < est.seconds / seconds < 2.0, (what, est.seconds, seconds)


def test_the_memory_estimate_is_within_2x_of_the_bench():
    m = bench()["memory"]
    est = cost.estimate(m["texels"], m["samples"], 3962, image_texels=m["resolution"] ** 2, threads=m["threads"])
    assert 0.5 < est.bytes / (m["peak_rss_mib"] * 2 ** 20) < 2.0, (est.bytes / 2 ** 20, m["peak_rss_mib"])


def test_the_bake_estimate_finds_the_covered_texels_from_the_uvs():
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    full = Mesh(P, F, uvs=P[F][:, :, :2], name="full")
    half = Mesh(P, F, uvs=P[F][:, :, :2] * [0.5, 1.0], name="half")
    assert cost.covered_fraction(full.uvs) == pytest.approx(1.0)
    assert cost.covered_fraction(half.uvs) == pytest.approx(0.5)
    a = cost.estimate_bake(full, resolution=256, samples=64)
    b = cost.estimate_bake(half, resolution=256, samples=64)
    assert b.seconds < a.seconds and 0.4 < (b.seconds - cost.FIXED_SECONDS) / (a.seconds - cost.FIXED_SECONDS) < 0.6
    # More processes: less time, more memory (each holds the scene).
    c = cost.estimate_bake(full, resolution=256, samples=64, threads=1, processes=4)
    assert c.seconds < a.seconds and c.bytes > a.bytes
    assert ("MiB" in a.describe() or "GiB" in a.describe())
    assert cost.Cost(0.4, 300 << 20).describe() == "under a second and 300 MiB"
    assert cost.Cost(12.3, 3 << 30).describe() == "about 12 s and 3.0 GiB"
