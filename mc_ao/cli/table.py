"""The table the script prints at the end of a run: one row per object baked (its size, time,
samples per texel, ray throughput and files)."""

from .. import summaries
from ..terminal import escape

HEADER = ("object", "size", "seconds", "samples/texel", "Mrays/s", "files")
#: A job's quantity (core.bake_ao's) as a row or a line names it.
QUANTITY_WORDS = {"ao": "AO", "thickness": "thickness"}


def row(name, result, settings, files):
    """The row of one baked object (``name`` escaped already)."""
    per_texel, rate = summaries.throughput(result)
    return (name, size_text(result, settings), f"{result.seconds:.2f}", f"{per_texel:.0f}", f"{rate:.2f}",
            escape(", ".join(files)))


def show(rows):
    """Print the rows under their header, each column as wide as its widest cell; nothing for no rows."""
    if not rows:
        return
    widths = [max(len(r[i]) for r in rows + [HEADER]) for i in range(len(HEADER))]
    for cells in [HEADER] + rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(cells, widths)).rstrip())


def size_text(result, settings):
    """The size column: WxH, WxH x N tiles (UDIM), or the face corners (colour attributes)."""
    w, h = settings.size
    if settings.vertex_colors:
        return f"{len(result.ao)} corners"
    if settings.use_udim:
        return f"{w}x{h} x{len(result.tiles)} tiles"
    return f"{w}x{h}"
