"""What the bench's sections share: bpy with the benchmark scene built, its arrays, the settings, the clock."""

from pathlib import Path

import numpy as np

from .common import ROOT, Clock

SCENE_COPY = Path(__file__).resolve().parents[1] / "data" / "scene_suzanne.npz"


class Context:
    """What the sections share: bpy, the scene's objects and its arrays, settings, the clock."""

    def __init__(self, cfg, threads):
        import bpy

        from . import scene

        self.bpy, self.cfg, self.threads = bpy, cfg, threads
        self.root = ROOT
        self.clock = Clock()
        self._scene = scene
        self._npz = None
        self.restore_scene()
        self.scene_npz()  # also what python -m bench.device bakes on the device machine

    def restore_scene(self):
        s = self._scene
        s.reset_blender(self.bpy)
        self.objs = s.build_scene(self.bpy)
        ta, oa = s.scene_arrays(self.bpy, "Suzanne")
        self.arrays = (ta, oa)
        self.target, self.occluders = s.core_meshes(ta, oa)

    def scene_npz(self):
        """The benchmark scene's arrays (target Suzanne and its occluders) as an .npz, for subprocesses."""
        if self._npz is None:
            ta, oa = self.arrays
            data = {"P": ta.positions, "F": ta.triangles, "UV": ta.uvs, "N": ta.normals,
                    "occluders": len(oa), "distance": self._scene.DISTANCE}
            for i, o in enumerate(oa):
                data[f"O{i}P"], data[f"O{i}F"] = o.positions, o.triangles
            SCENE_COPY.parent.mkdir(exist_ok=True)
            np.savez_compressed(SCENE_COPY, **data)
            self._npz = SCENE_COPY
        return self._npz
