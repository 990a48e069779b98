"""Exceptions of the core: each names the object and the problem, and is raised before heavy work.

Every class derives from one of the builtin types a caller would expect (ValueError for bad values,
TypeError for bad types, MemoryError for a bake too large for the machine, OSError for file
trouble), so ``except ValueError`` keeps working, and from :class:`McAoError`, so a caller such as
the Blender operator can catch everything the core raises on purpose in one clause.
"""


class McAoError(Exception):
    """Base of every exception the core raises deliberately."""


class MeshError(McAoError, ValueError):
    """A mesh's arrays are malformed: wrong shape, non-finite values, indices out of range, empty."""


class MeshTypeError(McAoError, TypeError):
    """A mesh array has a dtype that cannot be used (for example complex or object arrays)."""


class SettingsError(McAoError, ValueError):
    """A bake or sampling setting is out of its range (samples < 1, resolution <= 0, ...)."""


class BakeMemoryError(McAoError, MemoryError):
    """The bake would need more memory than the machine has; raised with the estimate, before allocating."""


class BakeCancelled(McAoError):
    """The bake was cancelled through its ``cancel`` argument; no partial result is returned."""


class FileWriteError(McAoError, OSError):
    """A file could not be written; any existing file at the path is left as it was."""


class ImageWriteError(FileWriteError):
    """An image file could not be written; any existing file at the path is left as it was."""


class ChannelError(SettingsError):
    """An image one channel of which is to be written does not allow it: it is missing or unreadable,
    has no such channel, has another size, or is in a format whose other channels could not be kept
    exactly as they are."""
