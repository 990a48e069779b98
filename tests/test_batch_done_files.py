"""When a batch task counts as done by its files: a file the bake wrote that carries no record of the
bake (a channel-packed copy of the Into image keeps that image's attributes) is taken as the bake's
only while it has the size and the modification time the bake's summary recorded; a file of the same
size written since is checked like any other (and, carrying no record, baked again). No Blender."""

import json
import os

import numpy as np

from core._version import OUTPUT_VERSION
from core.files import imageio
from mc_ao_batch.manifest import Task
from mc_ao_batch.task import why_not_done


def a_task_with_a_packed_copy(tmp_path):
    out = tmp_path / "out" / "chair"
    out.mkdir(parents=True)
    task = Task(index=1, name="chair", blend=str(tmp_path / "chair.blend"), blend_given="chair.blend",
                output=str(out), args=[], fingerprint="0123456789abcdef" * 4)
    copy = out / "orm.png"
    imageio.write_image(str(copy), np.full((16, 16, 3), 0.5, np.float32), bits=8)  # no mc_ao metadata
    st = os.stat(copy)
    summary = {"output_version": OUTPUT_VERSION, "exit_code": 0, "error": None, "settings": {},
               "objects": [{"object": "Block", "status": "ok", "files": [str(copy)],
                            "file_stats": {"orm.png": [st.st_size, st.st_mtime_ns]}, "error": None}]}
    with open(task.summary, "w") as f:
        json.dump(summary, f)
    return task, copy


def test_the_file_the_bake_wrote_counts_as_done(tmp_path):
    task, _ = a_task_with_a_packed_copy(tmp_path)
    assert why_not_done(task) is None


def test_a_file_of_the_same_size_written_since_is_baked_again(tmp_path):
    task, copy = a_task_with_a_packed_copy(tmp_path)
    data = bytearray(copy.read_bytes())
    st = os.stat(copy)
    data[-20] ^= 0xFF  # another tool's bytes, the same length
    copy.write_bytes(bytes(data))
    os.utime(copy, ns=(st.st_atime_ns, st.st_mtime_ns + 2_000_000_000))
    assert os.stat(copy).st_size == st.st_size
    why = why_not_done(task)
    assert why is not None and str(copy) in why, why
