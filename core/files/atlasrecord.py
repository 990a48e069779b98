"""What an atlas bake leaves for the next one: the record a rebake starts from.

A rebake bakes only the targets whose fingerprint changed and keeps every other texel as it was, and
its result must be bit for bit the result of baking the whole atlas again. The image itself cannot
hold what that takes: its covered texels are overwritten by the margins and may be rounded to 8 or
16 bits. So an atlas bake's result carries an :class:`AtlasRecord`: each target's name and
fingerprint, which target owns each covered texel, and the covered texels' values before margins
(float32, as baked: the AO, its standard error, the samples taken, the raw estimate before the
denoiser, the bent normals). A rebake takes the kept targets' texels from it.

Where it is kept: beside the image's files as ``<stem>.atlas.npz`` (:func:`sidecar_path`), and in
Blender on the image itself (the add-on's business). The format is numpy's ``.npz`` (zip of ``.npy``
arrays, deflated), read without pickles: nothing in it runs code, and a damaged or foreign file is
refused with a :class:`core.SettingsError` naming it.
"""

import io
import json
import os
import zipfile
from dataclasses import dataclass, field

import numpy as np

from .._version import OUTPUT_VERSION
from ..base.errors import FileWriteError, SettingsError
from . import atomicfile

#: The record's format (a reader refuses a record of a later format).
FORMAT = 1
#: What a sidecar's name adds to the image's stem.
SIDECAR_SUFFIX = ".atlas.npz"
#: The arrays of a record beside ``owner``: each covered texel's, in the order of the covered texels
#: (row by row). None where the bake made none.
PLANES = ("ao", "stderr", "samples", "mask", "raw_ao", "raw_stderr", "bent")


@dataclass
class AtlasRecord:
    """One quantity's atlas as a rebake needs it.

    width, height : the image's size.
    names, fingerprints : each target's name and fingerprint (tuples, in the bake's list order; a
        fingerprint says what the target's texels depend on: :func:`core.targets.atlas.fingerprints`).
    owner : (H, W) int32, the index (into ``names``) of the target owning each texel its UVs cover,
        -1 for a texel no target covers (margins are not recorded: they are made again every time).
    ao, stderr : (n,) float32; samples : (n,) int32; mask : (n,) bool, False for an owned texel the
        bake left to the margin (selected to active: no sample point found the high-poly); raw_ao,
        raw_stderr : (n,) float32 or None (the estimate before the denoiser); bent : (n, 3) float32 or
        None: the owned texels' values, in the order of ``np.flatnonzero(owner >= 0)``.
    quantity : 'ao' or 'thickness'; output_version : :data:`core._version.OUTPUT_VERSION` of the
        bake that made it; extra : plain data the caller keeps with it (JSON).
    """

    width: int
    height: int
    names: tuple
    fingerprints: tuple
    owner: np.ndarray
    ao: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    mask: np.ndarray = None
    raw_ao: np.ndarray = None
    raw_stderr: np.ndarray = None
    bent: np.ndarray = None
    quantity: str = "ao"
    output_version: int = OUTPUT_VERSION
    extra: dict = field(default_factory=dict)

    @property
    def covered(self):
        """Flat indices of the covered texels (the order of the planes)."""
        return np.flatnonzero(self.owner.reshape(-1) >= 0)

    def index(self, name):
        """The index of target ``name``, or None."""
        try:
            return self.names.index(name)
        except ValueError:
            return None

    def to_bytes(self):
        """The record as the bytes of a ``.npz`` file."""
        meta = dict(format=FORMAT, width=int(self.width), height=int(self.height), names=list(self.names),
                    fingerprints=list(self.fingerprints), quantity=self.quantity,
                    output_version=int(self.output_version), extra=self.extra)
        arrays = {"meta": np.frombuffer(json.dumps(meta).encode("utf-8"), np.uint8),
                  "owner": np.ascontiguousarray(self.owner, np.int32)}
        for name in PLANES:
            value = getattr(self, name)
            if value is not None:
                arrays[name] = np.ascontiguousarray(value)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data, what="the atlas record"):
        """The record of :meth:`to_bytes`' bytes; SettingsError naming ``what`` when they are not one."""
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                meta = json.loads(bytes(z["meta"]).decode("utf-8"))
                arrays = {name: z[name] for name in ("owner",) + PLANES if name in z.files}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, UnicodeDecodeError, EOFError) as exc:
            raise SettingsError(f"{what} cannot be read as an atlas record ({exc})") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise SettingsError(f"{what} is an atlas record of format {meta.get('format') if isinstance(meta, dict) else '?'}"
                                f", not {FORMAT}: bake the whole atlas again")
        try:
            record = cls(int(meta["width"]), int(meta["height"]), tuple(meta["names"]), tuple(meta["fingerprints"]),
                         arrays["owner"], arrays["ao"], arrays["stderr"], arrays["samples"], arrays.get("mask"),
                         arrays.get("raw_ao"), arrays.get("raw_stderr"), arrays.get("bent"), meta["quantity"],
                         int(meta["output_version"]), meta.get("extra") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise SettingsError(f"{what} is an incomplete atlas record (no {exc})") from None
        record.check(what)
        return record

    def check(self, what="the atlas record"):
        """Raise SettingsError naming ``what`` when the record's parts do not fit together."""
        n = int(np.count_nonzero(self.owner >= 0))
        problems = []
        if self.owner.shape != (self.height, self.width) or self.owner.dtype != np.int32:
            problems.append(f"its owner map is {self.owner.dtype} {self.owner.shape}, not int32 "
                            f"({self.height}, {self.width})")
        elif self.owner.size and int(self.owner.max()) >= len(self.names):
            problems.append(f"its owner map names target {int(self.owner.max())} of {len(self.names)}")
        if len(self.fingerprints) != len(self.names) or len(set(self.names)) != len(self.names):
            problems.append("its names and fingerprints do not match")
        for name in PLANES:
            value = getattr(self, name)
            if value is not None and len(value) != n:
                problems.append(f"its {name} holds {len(value)} texels, not the {n} covered")
        if problems:
            raise SettingsError(f"{what} is damaged: {'; '.join(problems)}; bake the whole atlas again")

    def write_to(self, target):
        """Write the record's bytes to ``target`` as they are (a caller that stages its files itself,
        as the add-on's all-or-none save does)."""
        with open(target, "wb") as f:
            f.write(self.to_bytes())

    def write(self, path):
        """Write the record to ``path`` (atomically, read back before it replaces anything)."""
        data = self.to_bytes()

        def write(temp):
            with open(temp, "wb") as f:
                f.write(data)

        def verify(temp):
            with open(temp, "rb") as f:
                if f.read() != data:
                    raise ValueError("it reads back different")

        return atomicfile.write_file(path, write, verify=verify, error=FileWriteError, ext=".npz")

    @classmethod
    def read(cls, path):
        """The record in the file ``path``; None when there is none; SettingsError when it is not one."""
        try:
            with open(path, "rb") as f:
                data = f.read()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise SettingsError(f"the atlas record {os.fspath(path)!r} cannot be read ({exc.strerror or exc})") from None
        return cls.from_bytes(data, f"{os.fspath(path)!r}")


def sidecar_path(image_path):
    """Where the record of the atlas saved as ``image_path`` goes: ``<folder>/<stem>.atlas.npz`` (one
    record for the stem's files of every format)."""
    folder, name = os.path.split(os.fspath(image_path))
    stem = os.path.splitext(name)[0]
    return os.path.join(folder, stem + SIDECAR_SUFFIX)


__all__ = ["AtlasRecord", "sidecar_path", "FORMAT", "SIDECAR_SUFFIX", "PLANES"]
