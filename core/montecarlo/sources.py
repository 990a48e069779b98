"""Sample sources by name: independent, stratified, Owen-scrambled Sobol' and permuted Halton points in
[0, 1)^d, one point set a module."""

from ..base.errors import SettingsError
from .sobol import Sobol
from .halton import Halton
from .stratified import Stratified
from .independent import Independent


SOURCES = {cls.name: cls for cls in (Independent, Stratified, Sobol, Halton)}


def make_source(name, d=2, seed=None):
    """Construct a sample source by name.

    Parameters
    ----------
    name : str
        One of the keys of :data:`SOURCES`: 'independent', 'stratified', 'sobol', 'halton'.
    d : int
        Dimension of the points.
    seed : None, int, SeedSequence or Generator
        Passed to the source.

    Returns
    -------
    Independent, Stratified, Sobol or Halton
    """
    try:
        cls = SOURCES[name]
    except (KeyError, TypeError):
        raise SettingsError(
            f"unknown sample source {name!r}; valid names: {', '.join(sorted(SOURCES))}"
        ) from None
    return cls(d, seed=seed)


__all__ = ["SOURCES", "make_source"]
