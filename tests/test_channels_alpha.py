"""Channel packing keeps the alpha's kind of the file it copies: a TIFF whose alpha is associated
(premultiplied colour, as compositing tools write them) stays associated, so that the other channels
keep their meaning; one whose alpha is unassociated stays so. Before, every copy said "unassociated",
and a reader then took the premultiplied colour as straight colour."""

import numpy as np
import pytest

OpenImageIO = pytest.importorskip("OpenImageIO")

from core.files.channels import write_channel  # noqa: E402


def tiff(path, fmt, associated):
    pixels = np.random.default_rng(3).random((8, 8, 4)).astype(np.float32)
    pixels[..., :3] *= pixels[..., 3:]  # colour premultiplied by alpha
    spec = OpenImageIO.ImageSpec(8, 8, 4, fmt)
    spec.alpha_channel = 3
    if not associated:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    out = OpenImageIO.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


def stored(path):
    """(samples as stored, whether the file says its alpha is unassociated)."""
    config = OpenImageIO.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = OpenImageIO.ImageInput.open(str(path), config)
    spec = inp.spec()
    data = inp.read_image(str(spec.format))
    inp.close()
    plain = OpenImageIO.ImageInput.open(str(path))
    unassociated = bool(plain.spec().get_int_attribute("tiff:UnassociatedAlpha", 0))
    plain.close()
    return np.asarray(data), unassociated


@pytest.mark.parametrize("fmt", ["uint8", "uint16", "float"])
@pytest.mark.parametrize("associated", [True, False])
def test_a_tiffs_alpha_keeps_its_kind(tmp_path, fmt, associated):
    source = tmp_path / "orm.tif"
    tiff(source, fmt, associated)
    before, was_unassociated = stored(source)
    assert was_unassociated == (not associated)
    copy = write_channel(tmp_path / "out.tif", "G", np.full((8, 8), 0.5, np.float32), source=source)
    after, now_unassociated = stored(copy)
    assert now_unassociated == was_unassociated
    assert after[..., [0, 2, 3]].tobytes() == before[..., [0, 2, 3]].tobytes()
