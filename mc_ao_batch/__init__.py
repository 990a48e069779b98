"""Batch baking of asset libraries: a TOML manifest of .blend files, one task (one process) per file.

No bpy here: the batch side plans tasks, runs ``scripts/bake_ao.py`` once per .blend file in a process
of its own (Blender, or a Python with the bpy module), and collects each run's ``--summary-json``. The
engines are other people's: a pool of local processes (``concurrent.futures``), Dask
(``distributed``), Flamenco and Open Job Description (``farm/``). See docs/batch.md.

- :mod:`mc_ao_batch.manifest`: reading and checking a manifest, planning its tasks.
- :mod:`mc_ao_batch.task`: one task: skip when done, else run the bake and read its summary.
- :mod:`mc_ao_batch.runners`: the local and the Dask runner.
- :mod:`mc_ao_batch.report`: progress, the table, the batch summary.
- :mod:`mc_ao_batch.farm`: Flamenco jobs and Open Job Description parameters.
- :mod:`mc_ao_batch.guard`: the process a task runs in, which ends the bake when its runner dies.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BAKE_SCRIPT = ROOT / "scripts" / "bake_ao.py"
