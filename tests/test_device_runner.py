"""bench.device, the many-core runner: its rows, and the work outside Embree it measures."""

import json

import numpy as np

from bench.sections import device
from bench.harness.report import table
from core import bake_ao
from scenes import plane


def test_a_constant_answer_bakes_everything_unoccluded_in_this_process_and_in_workers():
    mesh = plane()
    for kw in (dict(threads=1), dict(workers=2)):
        blocked = bake_ao(mesh, [_lid()], resolution=16, samples=4, margin=0, constant_answer=True, **kw)
        assert np.all(blocked.ao[blocked.mask] == 1.0)
    # With Embree, the lid occludes.
    assert bake_ao(mesh, [_lid()], resolution=16, samples=4, margin=0).ao[blocked.mask].mean() < 0.9


def _lid():
    from core import Mesh

    P = np.array([[-5.0, -5, 0.05], [5, -5, 0.05], [5, 5, 0.05], [-5, 5, 0.05]])
    return Mesh(P, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")


def test_serial_share_is_amdahls():
    assert device.serial_share(1, 1.0) is None
    assert device.serial_share(2, 2.0) == 0.0 and device.serial_share(2, 1.0) == 1.0
    f = 0.3
    for n in (2, 4, 16):
        assert abs(device.serial_share(n, 1.0 / (f + (1 - f) / n)) - f) < 1e-12


def test_the_runner_writes_every_row_and_the_report_shows_them(tmp_path):
    out = tmp_path / "device.json"
    device.main(["--res", "32", "--spp", "4", "--threads", "1", "2", "--workers", "1", "2", "--out", str(out)])
    data = json.loads(out.read_text())
    assert [r["threads"] for r in data["rows"]] == [1, 2]
    assert [r["workers"] for r in data["worker_rows"]] == [1, 2]
    for r in data["rows"] + data["worker_rows"]:
        assert r["seconds"] > 0 and r["outside_embree_seconds"] > 0 and r["outside_embree_speedup"] > 0
    assert data["rows"][0]["outside_embree_serial_share"] is None
    assert data["rows"][1]["outside_embree_serial_share"] is not None
    assert data["worker_rows"][1]["outside_embree_serial_share"] is not None
    latest = json.loads((device.ROOT / "bench" / "results" / "latest.json").read_text())
    latest["results"]["device"] = data
    text = table(latest)
    assert "outside embree" in text and "serial share" in text
