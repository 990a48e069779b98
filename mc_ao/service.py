"""One bake, the same for the operator, the script and the batch: plan -> run -> an Outcome per object.

- :func:`plan`: the outputs of the bake (mc_ao.outputs' kinds that apply to the settings), their
  Blender data checked (with ``check_blender``) and their files planned and checked, all before
  anything is baked; raises what is wrong, naming the object;
- :class:`Bake`: a run of the plan's jobs on a worker thread (mc_ao.bakerun.BakeRun); each message
  goes to ``handle``, which finishes a baked object through every output kind's steps (store into
  Blender, save its files all or none, keep) and hands the caller an :class:`Outcome`;
- :class:`Outcome`: what became of one object: "ok", "failed" (the core refused it, it baked
  nothing, or Blender's data could not take it), "crashed" (a bug; ``trace``), "cancelled";
  for a baked object, the files written, or why none were (``file_error``), its warnings and its
  summary line.

The operator (mc_ao.operators, modal: live tiles, progress, Esc, undo) and the script (mc_ao.cli:
progress on stderr, the summary JSON, Ctrl-C) are the two callers; the batch runs the script. No
bpy at import: storing into Blender (``store``) imports it.
"""

from dataclasses import dataclass, field

from . import bakerun, filewriter, interrupts, outputs, summaries
from .extract import ExtractError


@dataclass
class Plan:
    """What a bake will do: its settings, jobs (one per object), output kinds and planned files."""

    settings: object
    jobs: list
    kinds: list
    folder: str = None  # the output folder; None: no files
    files: dict = field(default_factory=dict)  # {image name: [mc_ao.filewriter.OutputFile]}

    @property
    def quantities(self):
        return outputs.quantities(self.kinds)

    def paths(self):
        """Every path the bake may write (images, standard errors, PLY)."""
        return outputs.planned_paths(self.files)


def plan(settings, jobs, folder=None, formats=None, check_blender=False):
    """The Plan of baking ``jobs`` with ``settings``; its files in ``folder`` in ``formats``
    ([(file_format, bits)]). Raises images.ImageError naming the object when ``check_blender`` and
    an existing image cannot take the bake, core.McAoError (FileWriteError, SettingsError) when a
    planned file cannot be written. Nothing is baked or changed."""
    kinds = outputs.kinds_for(settings)
    from . import atlas

    # Shared images: their sizes and the records of their earlier bakes (an object's own image that
    # holds other objects' texels becomes a shared one that keeps them).
    jobs = atlas.prepare(jobs, settings, folder, formats, in_blender=check_blender)
    if check_blender:
        from . import images

        for job in jobs:
            try:
                outputs.check(kinds, job)
            except images.ImageError as exc:
                raise images.ImageError(f"{job.object_name}: {exc}") from None
    files = outputs.plan_files(kinds, folder, jobs, formats) if folder is not None else {}
    return Plan(settings, jobs, kinds, folder, files)


@dataclass
class Outcome:
    """What became of one object of a bake (see the module's docstring)."""

    index: int
    job: object
    status: str  # "ok", "failed", "crashed", "cancelled"
    results: dict = None  # {quantity: core result} of a baked object (None: the job's own bake)
    error: str = None  # why it failed (without the object's name)
    trace: str = None  # a crash's traceback
    files: list = field(default_factory=list)  # the paths written
    file_error: str = None  # a baked object whose files were not written (none of them): why
    notes: list = field(default_factory=list)  # warnings (without the object's name)
    summary: str = None  # its summary line (an image kind's, a colour attribute's)
    where: str = ""  # where the bake is in Blender ("image 'X_AO'"), for the file error's message

    @property
    def object_name(self):
        return self.job.object_name

    @property
    def result(self):
        """The core's result of the job's own bake, or None."""
        return self.results.get(None) if self.results else None

    @property
    def baked(self):
        return self.status == "ok"


class Bake:
    """One run of a Plan: the worker, its messages, and each finished object through its outputs.

    Parameters
    ----------
    plan : Plan
    threads : int or None
        The worker threads (None: every core).
    live : bool
        The worker also sends each finished tile (the operator's live image).
    store : mc_ao.outputs.store.Store or None
        Where the kinds put the bake into Blender (the operator); None: files only (the script).
    store_kinds : set of str or None
        With a store, the kinds that use it (None: every kind).
    blend : str
        The .blend file's path, for the files' metadata.
    store_after_save : bool
        Store into Blender only once the object's files are written (see finish()).
    hold_interrupts : bool
        Finish each object with Ctrl-C held off (the script): an interrupt then comes after its
        files are written and its outcome handed over, never between two of its files.
    """

    def __init__(self, plan, threads=None, live=False, store=None, store_kinds=None, blend="",
                 hold_interrupts=False, store_after_save=False):
        self.plan = plan
        self.store_after_save = store_after_save
        self.store = store
        self.store_kinds = store_kinds
        self.blend = blend
        self.hold_interrupts = hold_interrupts
        self.worker = bakerun.BakeRun(plan.jobs, plan.settings, threads, live, quantities=plan.quantities)
        self.outcomes = {}  # job index -> Outcome, as they come
        self._handler = None

    @property
    def jobs(self):
        return self.plan.jobs

    @property
    def thread(self):
        return self.worker.thread

    @property
    def started(self):
        return self.worker.started

    @property
    def messages(self):
        return self.worker.messages

    def start(self):
        self.worker.start()

    def stop(self):
        self.worker.stop()

    def next_message(self):
        return self.worker.next_message()

    def handle(self, message, handler):
        """Apply one worker message; True at the end of the run.

        ``handler`` gets ``on_progress(i, fraction)`` and ``on_tile(i, rows, cols, block)`` as they
        come (where it has them), and ``on_outcome(outcome)`` once per object that ended.
        """
        self._handler = handler
        return bakerun.dispatch(message, self)

    def cancel_rest(self):
        """Outcomes "cancelled" for every job that has none (after a stop); returns them."""
        rest = [Outcome(i, job, "cancelled") for i, job in enumerate(self.jobs) if i not in self.outcomes]
        for outcome in rest:
            self.outcomes[outcome.index] = outcome
        return rest

    # -- bakerun.dispatch's handler --------------------------------------------------------------

    def on_progress(self, i, fraction):
        method = getattr(self._handler, "on_progress", None)
        if method is not None:
            method(i, fraction)

    def on_tile(self, i, rows, cols, block):
        method = getattr(self._handler, "on_tile", None)
        if method is not None:
            method(i, rows, cols, block)

    def on_done(self, i, results):
        if self.hold_interrupts:  # a Ctrl-C now comes once the object's files and outcome are in
            with interrupts.held_off():
                self._end(self.finish(i, results))
        else:
            self._end(self.finish(i, results))

    def on_failed(self, i, exc):
        self._restore(i)
        self._end(Outcome(i, self.jobs[i], "failed", error=str(exc)))

    def on_crashed(self, i, exc, trace):
        self._restore(i)
        self._end(Outcome(i, self.jobs[i], "crashed", error=f"bake failed ({type(exc).__name__}: {exc})", trace=trace))

    def on_cancelled(self, i):
        pass  # the caller stopped the run; it ends the remaining jobs (cancel_rest)

    def _end(self, outcome):
        self.outcomes[outcome.index] = outcome
        self._handler.on_outcome(outcome)

    def _restore(self, i):
        if self.store is not None:
            self.store.restore(i)

    # -- one finished object ---------------------------------------------------------------------

    def _stores(self, kind):
        return self.store is not None and (self.store_kinds is None or kind.name in self.store_kinds)

    def finish(self, i, results):
        """Job ``i`` baked: every output kind stores it into Blender, its files are saved (all or
        none), the stored data is kept; its Outcome. With ``store_after_save``, the kinds store only
        after the files were written (the script: nothing goes into the .blend it saves for an
        object whose files failed)."""
        job = self.jobs[i]
        outcome = Outcome(i, job, "ok", results)
        if self.store is not None:
            self.store.current, self.store.object_name, self.store.notes = i, job.object_name, outcome.notes
        stored = [] if self.store_after_save else self._store_all(i, outcome)
        if stored is None:
            return outcome
        saved = self._save(outcome) if self.plan.folder is not None else {}
        if self.store_after_save and not outcome.file_error:
            stored = self._store_all(i, outcome)
            if stored is None:
                return outcome
        for kind in stored:
            kind.keep(self.store, job, results, saved.get(kind, []))
        if self.store is not None:
            self.store.finished(i)
            self.store.notes = None
        outcome.notes.extend(summaries.input_notes(results[None]))
        if getattr(job, "atlas", False):  # several objects in one image: their overlaps, an unlimited reach
            from . import atlas

            outcome.notes.extend(atlas.notes(results[None]))
        outcome.summary = next((s for s in (k.summarise(job, results) for k in self.plan.kinds) if s), None)
        return outcome

    def _store_all(self, i, outcome):
        """The kinds that store into Blender, stored; None when one failed (the outcome then says
        why, and the images of the object are put back). Without a Blender store (the service run
        outside Blender) nothing is stored and bpy is not imported."""
        if self.store is None:
            return []
        from . import images

        job, settings, stored = outcome.job, self.plan.settings, []
        for kind in self.plan.kinds:
            if not self._stores(kind):
                continue
            try:
                kind.store(self.store, job, outcome.results)
            except (images.ImageError, ExtractError, RuntimeError) as exc:
                if getattr(kind, "optional", False):
                    outcome.notes.append(f"the {kind.name.replace('_', ' ')} was not kept: {exc}")
                    continue
                self._restore(i)
                outcome.status, outcome.error = "failed", str(exc)
                if self.store is not None:
                    self.store.notes = None
                return None
            stored.append(kind)
        if stored:
            outcome.where = (f"color attribute {settings.attribute_name!r}" if settings.vertex_colors
                             else f"image {job.image_name!r}")
        return stored

    def _save(self, outcome):
        """Write the object's files, all or none; {kind: its paths written}."""
        job, results = outcome.job, outcome.results
        metadata = filewriter.file_metadata(self.plan.settings, job, self.blend)
        writes = [(kind, w) for kind in self.plan.kinds for w in kind.writes(job, results, self.plan.files, metadata)]
        # in the planned order (each image's files with its standard error), tile by tile
        rank = {p: k for k, p in enumerate(self.plan.paths())}
        writes.sort(key=lambda kw: (kw[1].tile or 0, rank.get(kw[1].planned or kw[1].path, len(rank))))
        saved = {}
        try:
            outcome.files = outputs.save_files([w for _, w in writes])
        except outputs.SaveError as exc:
            outcome.file_error = str(exc)
        else:
            for kind, w in writes:
                saved.setdefault(kind, []).append(w.path)
        return saved


def not_written(file_error):
    """What became of the files of a baked object one of whose files failed (``file_error``, the
    failure): none was written, each file already there is as it was (the files are written all or
    none, mc_ao.outputs.save_files)."""
    return f"none of its files was written (any file already there is unchanged): {file_error}"


def file_error_message(outcome):
    """The report of a baked object whose files were not written: where the bake is, that none of
    its files was written (the old ones unchanged), and which failed."""
    where = f"the bake is in {outcome.where}, but" if outcome.where else "the bake finished, but"
    return f"{outcome.object_name}: {where} {not_written(outcome.file_error)}"

