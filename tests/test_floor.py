"""bench.sections.floor's stages (the per-ray floor the ceiling's target is read against): every form of a
stage computes the same numbers, so the cheapest form it counts does the work the kernel does."""

import numpy as np
import pytest

from bench.sections.floor import Chunk, prepare, stage_forms


@pytest.mark.parametrize("columns", [6, 11])
def test_every_form_of_a_stage_computes_the_same(columns):
    c = Chunk(32, columns, seed=4)
    s = c.texels(1)
    c.gather_rows(s)
    c.gather_planes(s)
    assert np.array_equal(c.x.view(np.uint32), c.x_rows.view(np.uint32).transpose(2, 0, 1))
    # Each texel's block is a whole aligned block of its pattern, in pool order.
    first = c.pattern[s] * 1024 + (c.order[s] & ~31)
    assert np.array_equal(c.x_rows[5].view(np.uint32), c.rows[first[5]:first[5] + 32].view(np.uint32))
    c.shift_rows(s)
    c.shift_planes(s)
    assert np.array_equal(c.x, c.x_rows.transpose(2, 0, 1))
    assert 0.0 <= c.x[0:2].min() and c.x[0:2].max() < 1.0
    c.offset_turn_planes(s)
    c.x_rows[...] = c.x.transpose(1, 2, 0)
    c.map_rows(s)
    c.map_planes_blas(s)
    assert np.allclose(c.y, c.y_rows.transpose(2, 0, 1), rtol=1e-5, atol=1e-5)
    blas = c.y.copy()
    c.map_planes_elementwise(s)
    assert np.allclose(c.y, blas, rtol=1e-5, atol=1e-5)
    # The map is the per-texel matrix: texel 3's rows through its own matrix.
    assert np.allclose(c.y[:, 3].T, c.x_rows[3] @ c.m[s[3]], rtol=1e-5, atol=1e-5)
    assert set(stage_forms(columns)) >= {"gather", "shift", "map", "sum"}
    assert ("finish" in stage_forms(columns)) == (columns == 11)


def test_the_smooth_finish_makes_cosine_directions_about_the_normal():
    c = Chunk(64, 11, seed=2)
    s = c.texels(0)
    prepare(c, "finish", s)
    c.finish_planes(s)
    n = c.y[3:6]
    d = c.dirs
    ln = np.sqrt((n * n).sum(axis=0))
    # direction = |n| (n / |n| + v): rows where tfar > 0 have a finite unit-length reciprocal.
    assert np.allclose(d, n + ln * c.y[6:9], rtol=1e-5, atol=1e-5)
    ok = c.tfar > 0
    assert np.allclose(c.tfar[ok] * np.sqrt((d * d).sum(axis=0))[ok], 1.0, rtol=1e-4)
    assert c.sum(s).shape == (c.t,)
