"""The Bake AO operator: modal with a worker thread from the UI, synchronous from scripts and -b.

The bake itself is mc_ao.service's, as for the script: a plan (one job per selected mesh and
quantity, its outputs and files checked before any work), a run on a worker thread that never
touches bpy and puts messages on a queue, and each finished object through its outputs (images,
files written all or none, colour attribute). A BakeSession is what only the UI adds: the selection,
the live image while a job bakes, the progress, Esc and undo, the reports. The operator drives it
from window-manager timer events when modal (Esc cancels) or in a blocking loop when not; the
tests drive it with the same events, since a modal operator cannot run without a window.

What goes wrong, and what the user gets (a report naming the object, images kept as they were):

- a selected object that is not a mesh, or a mesh without a UV map: skipped with a warning; with
  nothing else selected the button is disabled and the panel and tooltip say why
- an existing image of another size: resized to the bake's size (reported); put back as it was
  when its bake does not finish
- an output folder that cannot be written: refused before baking, nothing changes; a file that
  fails to write later: the image in Blender keeps the bake, and none of that object's files is
  written (each file on disk is left as it was); the report names the file that failed
- Esc, Undo during a bake, or a failure in the core: unfinished images are put back as they were,
  finished ones are kept; a failed object does not stop the others

What a finished bake leaves: its image, with a fake user, packed into the .blend (or, with Save to
File and Link to File on, loading from the saved file), so that File > Save keeps it and no later
undo or redo step blanks it; Blender's undo keeps no pixels of an unpacked image whose settings
changed. The report of each object ends with its summary (size, time, samples, rays/s), after its
warnings, since the status bar shows only the last report.
"""

import queue
import sys
import time
import traceback

import bpy

from . import bakerun, baking, corelink, filecheck, filewriter, images, precheck, rules, schema, service, undo_images, vertex_colors
from .choose import ChoiceError, Pick, choose
from .extract import ExtractError
from .outputs.store import Store
from .properties import resolve_threads
from .settings import BakeSettings
from .terminal import escape

# Bakes in flight, so that unregister() can stop their threads (BakeRun adds and removes itself).
_RUNS = bakerun.RUNS
# Sessions in flight, so that an undo can end them before it replaces the data they write to.
_SESSIONS = set()
# Seconds between two live updates of an image, at least: writing a 1024 x 1024 image's pixels takes
# milliseconds. A larger image's update takes longer (8192 x 8192: about a second on the main thread),
# so the next one waits LIVE_DUTY times as long as the last took: the UI stays responsive.
LIVE_UPDATE_INTERVAL = 0.25
LIVE_DUTY = 10
TIMER_INTERVAL = 0.1
# Live updates keep an RGBA float copy of the image (16 bytes a texel): beyond 8192 x 8192 (1 GiB)
# the image is written once, at the end.
LIVE_MAX_TEXELS = 8192 * 8192


class OutputError(ValueError):
    """The output folder for saved files cannot be used; raised before any baking."""


def _output_dir(settings):
    """Absolute folder for saved files; OutputError when it is unset, relative to an unsaved .blend
    file, or cannot be written (a file in its path, no permission)."""
    if not settings.output_dir.strip():
        raise OutputError("Save to File is on but no output folder is set; nothing was baked")
    if settings.output_dir.startswith("//") and not bpy.data.filepath:
        raise OutputError(
            f"the output folder {settings.output_dir!r} is relative to the .blend file, "
            "which is not saved yet; save it or choose an absolute folder"
        )
    folder = bpy.path.abspath(settings.output_dir)
    problem = filecheck.folder_problem(folder)
    if problem is not None:
        raise OutputError(f"Cannot save into the output folder {folder!r}: {problem}; nothing was baked")
    return folder


def _redraw(context):
    """Redraw the editors that show images or the panel: Blender redraws them on events only."""
    if context.window_manager is None:
        return
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in {"IMAGE_EDITOR", "VIEW_3D"}:
                area.tag_redraw()


def show_in_image_editors(context, image):
    """Show ``image`` in every open Image Editor that is free to show it: not pinned to its image, not
    painting or editing a mask; the image a bake fills in is then in view while it fills in."""
    wm = getattr(context, "window_manager", None)
    if wm is None or image is None:
        return
    for window in wm.windows:
        for area in window.screen.areas:
            if area.type != "IMAGE_EDITOR":
                continue
            space = area.spaces.active
            if space.use_image_pin or getattr(space, "mode", "VIEW") != "VIEW" or space.image == image:
                continue
            space.image = image
            area.tag_redraw()


def estimated_seconds(context, settings, choice):
    """The uncalibrated estimate (mc_ao.baking.bake_cost) of baking ``choice`` in ``context``, as the
    panel prices it; None where it cannot be made."""
    from . import selected_to_active

    try:
        kwargs = {}
        if settings.use_selected_to_active:
            active, cage = context.active_object, selected_to_active.cage_of(context.scene.mc_ao)
            kwargs = dict(highpoly=selected_to_active.high_objects(context.selected_objects, active, cage), cage=cage)
        return baking.bake_cost(settings, choice.targets, context.evaluated_depsgraph_get(),
                                selected=context.selected_objects, view_layer=context.view_layer,
                                threads=resolve_threads(context, settings), **kwargs).seconds
    except Exception:  # an estimate is never a reason not to bake
        return None


def why_not(context):
    """Why the Bake AO button is disabled in ``context`` (the poll message, the panel's hint), or None."""
    return choice_of(context)[1]


def choice_of(context):
    """``(choice, None)``: what Bake AO would bake in ``context`` (mc_ao.choose.Choice, no geometry
    read), or ``(None, why not)``."""
    props = getattr(context.scene, "mc_ao", None)
    settings = BakeSettings() if props is None else BakeSettings.from_properties(props).in_effect()
    for field, message in rules.broken(settings, schema.label_of, poll=True):
        return None, f"{schema.label_of(field)} {message}"
    try:
        choice = choose(settings, Pick(list(context.selected_objects), context.active_object), context.view_layer)
    except ChoiceError as exc:
        return None, str(exc)
    # What the checks after the click would refuse, where names and datablocks tell it cheaply.
    problem = precheck.problem(settings, choice.targets, bpy.data.images)
    if problem is not None:
        return None, problem
    if settings.vertex_colors:
        # A color attribute bake that every selected mesh's modifiers make impossible is greyed out
        # too, with the reason, rather than refused after the click.
        depsgraph = context.evaluated_depsgraph_get() if hasattr(context, "evaluated_depsgraph_get") else None
        problems = [vertex_colors.modifier_problem(obj, depsgraph) for obj in choice.targets]
        if problems and all(problems):
            return None, problems[0] if len(problems) == 1 else "; ".join(problems)
    return choice, None


def is_running():
    """Whether an AO bake is in progress (the panel says so, the operator refuses a second one)."""
    return bool(_RUNS)


# The last report of the last bake that ended or was refused ("INFO" | "WARNING" | "ERROR", text), or
# None: the panel shows it under the button until the next bake, since the status bar shows a report
# for a few seconds only (and Blender 4.3 showed none at all after a finished modal bake). It
# belongs to the file it was baked in: opening or starting another file forgets it.
last_outcome = None


def set_outcome(report):
    """Remember ``report`` (type, text) as the last bake's outcome, or forget it (None)."""
    global last_outcome
    last_outcome = report


@bpy.app.handlers.persistent
def forget_outcome(*_args):
    """load_post handler: another file is open; the last bake's line and the estimate's counts of
    occluders were about the one before."""
    set_outcome(None)
    baking.forget_occluder_counts()
    undo_images.forget()


@bpy.app.handlers.persistent
def forget_occluder_counts(*_args):
    """depsgraph_update_post handler: Blender's data changed; the estimate counts the occluders again."""
    baking.forget_occluder_counts()


@bpy.app.handlers.persistent
def stop_bakes_before_undo(*_args):
    """undo_pre / redo_pre handler: stop the workers of running bakes before the undo runs.

    An undo frees and re-reads datablocks, and Blender's undo stores no image pixels: a bake that
    went on writing into its images across it would write into what the undo took back, and the
    images' previous content would be lost. HANDLERS lists where each handler goes.
    """
    for session in list(_SESSIONS):
        session.interrupt()


@bpy.app.handlers.persistent
def end_bakes_after_undo(*_args):
    """undo_post / redo_post handler: end the stopped bakes, putting back the images' previous pixels."""
    for session in list(_SESSIONS):
        if session.interrupted:
            session.finish(bpy.context, cancelled=True, why="by Undo")
    undo_images.after_undo()  # baked images show the pixels of the step undo or redo came to


# bpy.app.handlers list name -> handler; register() appends them, unregister() removes them.
HANDLERS = {
    "undo_pre": stop_bakes_before_undo,
    "redo_pre": stop_bakes_before_undo,
    "undo_post": end_bakes_after_undo,
    "redo_post": end_bakes_after_undo,
    "load_post": forget_outcome,
    "depsgraph_update_post": forget_occluder_counts,
}


def total_summary(results, objects=None, quantities=("ao",)):
    """One line for a bake of several maps: the objects' number (``objects``, default one a result:
    an object baked for AO and thickness is one object, two results), time, samples per texel, ray
    throughput; the quantities when more than AO."""
    seconds = sum(r.seconds for r in results)
    rays = sum(r.rays for r in results)
    covered = sum(int(r.mask.sum()) for r in results)
    per_texel = sum(float(r.samples[r.mask].sum()) for r in results) / covered if covered else 0.0
    rate = rays / seconds / 1e6 if seconds > 0 else float("nan")
    n = len(results) if objects is None else objects
    what = f" ({' and '.join(QUANTITY_WORDS.get(q, q) for q in quantities)})" if tuple(quantities) != ("ao",) else ""
    return (
        f"AO bake: {n} object{'s' if n != 1 else ''}{what} in {seconds:.2f} s, {per_texel:.0f} samples per "
        f"texel, {rate:.2f} M rays/s"
    )


#: A quantity (core.bake_ao's) as a summary names it.
QUANTITY_WORDS = {"ao": "AO", "thickness": "thickness"}


def with_warnings(text, warnings, errors=0):
    """``text`` with how many warnings and errors came before it (the status bar shows only the last)."""
    counts = [f"{n} {word}{'s' if n > 1 else ''}" for n, word in ((errors, "error"), (warnings, "warning"))
              if n]
    if not counts:
        return text
    return f"{text}; {' and '.join(counts)} before this, in the Info editor"


class BakeSession:
    """The operator's side of one bake (mc_ao.service): plan it, run it, show it, report it, end it.

    ``report(type, message)`` is the operator's ``self.report`` (or anything that takes the same).
    The service's Bake finishes each object (its images, files, colour attribute); this session
    adds what only the UI has: the live image while the bake runs, the progress, Esc and undo, and
    the reports. Images are prepared when a job first writes into them, with a snapshot
    (mc_ao.outputs.store.Store); every image whose job did not finish is put back at the end, so a
    cancelled or failed bake leaves no partial image.
    """

    def __init__(self, report):
        self._report_to = report
        self.last_report = None  # (type, message) of the last report, for the panel
        self.run = None
        self.area = None  # the area whose header shows the progress (modal only)
        self.ended = None  # the operator's result, once the session has ended
        self.interrupted = False  # an undo stopped the worker; the session ends after it

    def report(self, kind, message):
        """The operator's report, remembered: the last one of a bake is what the panel shows. Escaped
        (mc_ao.terminal): the names in it may hold escape sequences or newlines, and Blender prints
        reports to the terminal in the background."""
        message = escape(message)
        self.last_report = (next(iter(kind)), message)
        self._report_to(kind, message)

    # -- setting up ---------------------------------------------------------------------------

    def start(self, context, live):
        """Plan the jobs and start the worker; False (after reporting) when there is nothing to do."""
        if is_running():
            self.report({"WARNING"}, "An AO bake is already running; Esc cancels it")
            return False
        missing = corelink.missing_dependency()
        if missing is not None:
            self.report({"ERROR"}, f"Cannot bake: {missing}")
            return False
        # What the panel shows as active: a greyed-out setting is neither used nor refused.
        self.settings = settings = BakeSettings.from_properties(context.scene.mc_ao).in_effect()
        problems = schema.problems(settings)
        if problems:
            # The properties' own limits keep most values in range; what gets past them (a script
            # setting a value, a limit of the core's) is refused here, before anything is baked.
            names = context.scene.mc_ao.bl_rna.properties
            self.report({"ERROR"}, "; ".join(
                f"{names[field].name if field in names else field} {message}" for field, message in problems
            ) + "; nothing was baked")
            return False
        try:
            # Nothing to bake: the poll refuses this already; a script that gets past it (or a changed
            # selection) hears the same reason.
            choice = choose(settings, Pick(list(context.selected_objects), context.active_object), context.view_layer)
        except ChoiceError as exc:
            self.report({"ERROR"}, str(exc))
            return False
        # What the panel estimated, beside what the bake will take: the panel's next estimates learn it.
        self.estimated, self.started = estimated_seconds(context, settings, choice), time.monotonic()
        try:
            folder = _output_dir(settings) if settings.save_to_file else None
            jobs = choice.jobs(context.evaluated_depsgraph_get())
            plan = service.plan(settings, jobs, folder, [(settings.file_format, settings.file_bits)],
                                check_blender=True)
        except (ExtractError, OutputError, images.ImageError, corelink.load().McAoError) as exc:
            self.report({"ERROR"}, str(exc))
            return False
        self.warnings = 0  # warnings reported, counted in the summary of the whole bake
        self.unsummarised = 0  # warnings since the last summary line, counted in the next one
        self.unsummarised_errors = 0  # errors (a file not saved) since the last summary line
        for obj in choice.skipped:
            self._warn(baking.skip_note(obj, settings.occluders, baking.needs_uvs(settings)))
        for job in plan.jobs:
            for note in job.notes:
                self._warn(f"{job.object_name}: {note}")
        w, h = settings.size
        # UDIM tiles and colour attributes are stored when their object's bake finishes; an existing
        # image shared by several objects when its bake finishes too (its other texels stay as they are).
        self.live = (live and w * h <= LIVE_MAX_TEXELS and not (settings.vertex_colors or settings.use_udim)
                     and not any(getattr(job, "atlas", False) and job.image_name in bpy.data.images
                                 for job in plan.jobs))
        self.errors = 0  # jobs whose bake failed
        self.failed_objects = set()  # their objects
        self.file_errors = 0  # objects baked whose files were not saved
        self.finished = []
        self.results = []  # of the finished jobs, for the summary of a bake of several objects
        self.buffers = {}  # job index -> live pixel buffer (H, W, channels)
        self.pending = set()  # jobs whose live buffer has tiles not yet in the image
        self.last_flush = 0.0
        self.live_interval = LIVE_UPDATE_INTERVAL
        self.fraction = 0.0
        self.store = Store(settings, folder, plan.files, lambda kind, text: self.report({kind}, text))
        self.run = service.Bake(plan, resolve_threads(context, settings), self.live, store=self.store,
                                blend=bpy.data.filepath)
        self.run.start()
        _SESSIONS.add(self)
        context.window_manager.progress_begin(0.0, 1.0)
        return True

    # -- the live image ------------------------------------------------------------------------

    def _buffer(self, i):
        """The live pixel buffer of job i (None when its image cannot take the bake)."""
        if i not in self.buffers:
            w, h = getattr(self.run.jobs[i], "size", None) or self.settings.size
            self.store.current, self.store.object_name = i, self.run.jobs[i].object_name
            try:
                image = self.store.image(self.run.jobs[i].image_name, w, h, self.settings.float_buffer, i=i)
                self.buffers[i] = images.pixels_of(image)
            except images.ImageError:
                self.buffers[i] = None  # reported when the job is done
            else:
                show_in_image_editors(self._context, image)
        return self.buffers[i]

    def _flush_live(self, context):
        now = time.monotonic()
        if not self.pending or now - self.last_flush < self.live_interval:
            return
        for i in self.pending:
            w, h = getattr(self.run.jobs[i], "size", None) or self.settings.size
            image = self.store.image(self.run.jobs[i].image_name, w, h, self.settings.float_buffer, i=i)
            buffer = self.buffers.get(i)
            if buffer is not None and tuple(image.size) == (buffer.shape[1], buffer.shape[0]):
                images.set_pixels(image, buffer)
        self.pending.clear()
        self.last_flush = time.monotonic()
        # Throttled by what an update costs: an 8k image's takes about a second of the main thread.
        self.live_interval = max(LIVE_UPDATE_INTERVAL, LIVE_DUTY * (self.last_flush - now))
        _redraw(context)

    def interrupt(self):
        """Stop the worker now, write nothing more; finish() follows (after the undo that called this)."""
        if self.ended is None and self.run is not None:
            self.run.stop()
            self.interrupted = True

    # -- the service's messages ------------------------------------------------------------------

    def _handle(self, context, message):
        """Apply one worker message (mc_ao.service.Bake.handle); True at the end of the run."""
        self._context = context
        return self.run.handle(message, self)

    def on_progress(self, i, fraction):
        self.fraction = (i + fraction) / len(self.run.jobs)
        self._context.window_manager.progress_update(self.fraction)

    def on_tile(self, i, rows, cols, block):
        buffer = self._buffer(i)
        if buffer is not None:
            buffer[rows, cols] = images.rgba(block, buffer.shape[2])
            self.pending.add(i)

    def on_outcome(self, outcome):
        """One object ended: report its errors, its files, its warnings, then its summary."""
        self.pending.discard(outcome.index)
        self.buffers.pop(outcome.index, None)
        name = outcome.object_name
        if not outcome.baked:
            self.errors += 1
            self.failed_objects.add(name)
            if outcome.trace:
                print(f"mc_ao: the bake of {name} failed:\n{outcome.trace}", file=sys.stderr)
            self.report({"ERROR"}, f"{name}: {outcome.error}" + ("; see the console" if outcome.trace else ""))
            return
        self.finished.append(outcome.index)
        self.results.append(outcome.result)
        if not self.live and not self.settings.vertex_colors:  # not shown while it filled in: shown now
            show_in_image_editors(self._context, bpy.data.images.get(outcome.job.image_name))
        if outcome.file_error:
            self.file_errors += 1
            self.unsummarised_errors += 1
            self.report({"ERROR"}, service.file_error_message(outcome))
        elif outcome.files:
            self.report({"INFO"}, f"{name}: saved {', '.join(outcome.files)} ({filewriter.writer_name()})")
        _redraw(self._context)
        for note in outcome.notes:
            self._warn(f"{name}: {note}")
        if outcome.summary:
            self._summarise(outcome.summary)

    def _warn(self, message):
        self.warnings += 1
        self.unsummarised += 1
        self.report({"WARNING"}, message)

    def _summarise(self, text):
        """Report ``text``, a summary, as a warning that counts the warnings and errors before it, if any."""
        warnings, errors = self.unsummarised, self.unsummarised_errors
        self.unsummarised = self.unsummarised_errors = 0
        self.report({"WARNING"} if warnings or errors else {"INFO"}, with_warnings(text, warnings, errors))

    def _next_message(self):
        # A timeout, so that Ctrl-C (KeyboardInterrupt) gets through while nothing arrives.
        while True:
            try:
                return self.run.messages.get(timeout=0.25)
            except queue.Empty:
                pass

    # -- driving it ----------------------------------------------------------------------------

    def wait(self, context):
        """Apply messages until the bake ends (scripts, background mode); return the operator's result."""
        try:
            while not self._handle(context, self._next_message()):
                pass
        except KeyboardInterrupt:
            return self.finish(context, cancelled=True)
        except Exception as exc:  # a bug here must not leave the worker running, nor reach the user as a trace
            return self.fail(context, exc)
        return self.finish(context)

    def fail(self, context, exc):
        """End the bake after an unexpected error on the main thread: report it, put the images back."""
        traceback.print_exc()
        self.report({"ERROR"}, f"AO bake stopped by an internal error ({type(exc).__name__}: {exc}); see the console")
        try:
            return self.finish(context, cancelled=True)
        except Exception:
            traceback.print_exc()
            self.abandon()
            return {"CANCELLED"}

    def on_event(self, context, event_type):
        """One modal event: Esc cancels, a timer tick applies the messages; returns the operator's result.

        {"PASS_THROUGH"} while the bake runs (the UI stays usable), the final result once it ended.
        """
        if self.ended is not None:  # ended from outside the modal (an undo)
            return self.ended
        if self.interrupted:  # stopped for an undo that did not come back to say it is done
            return self.finish(context, cancelled=True, why="by Undo")
        if event_type == "ESC":
            return self.finish(context, cancelled=True)
        if event_type != "TIMER":
            return {"PASS_THROUGH"}
        ended = False
        while not ended:
            try:
                ended = self._handle(context, self.run.messages.get_nowait())
            except queue.Empty:
                break
        if ended:
            return self.finish(context)
        self._flush_live(context)
        self._show_progress(context)
        return {"PASS_THROUGH"}

    def finish(self, context, cancelled=False, why=""):
        """End the bake: stop the worker, put back unfinished images, report; the operator's result.

        {"FINISHED"} when at least one object was baked and the bake was not cancelled, else
        {"CANCELLED"}. Calling it again returns the same result.
        """
        if self.ended is not None:
            return self.ended
        self.run.stop()
        _SESSIONS.discard(self)
        # After an undo, an image the bake created is already gone (the undo went back to before
        # it) and a datablock of that name is the undo's: only reused images are put back then.
        self.store.restore_all(created=not self.interrupted)
        self.buffers.clear()
        self.pending.clear()
        try:
            context.window_manager.progress_end()
            self.set_texts(context, None)
            _redraw(context)  # restored images, and the panel without its "Baking" line
        except (AttributeError, ReferenceError, RuntimeError):
            pass
        # Objects, not jobs: an object baked for AO and thickness is one object of two jobs.
        done = [name for name in dict.fromkeys(self.run.jobs[i].object_name for i in self.finished)
                if name not in self.failed_objects]
        total = len({job.object_name for job in self.run.jobs})
        if cancelled:
            kept = f"kept the finished bakes of {', '.join(done)}; the other images" if done else "the images"
            files = ""
            if self.run.plan.folder is not None:  # each object's files are written together or not at all
                saved = [o.object_name for o in self.run.outcomes.values() if o.baked and o.files]
                files = (f"; every file of {', '.join(saved)} is written, none of the others'" if saved
                         else "; no file was written")
            self.report({"WARNING"}, f"AO bake cancelled{' ' + why if why else ''}; {kept} are as they were{files}")
            self.ended = {"CANCELLED"}
        else:
            if self.errors and total > 1:
                self.report(
                    {"WARNING"},
                    f"AO bake: {len(done)} of {total} objects baked, the failed ones' images are as they were",
                )
            elif len(self.results) > 1:
                self.unsummarised = self.warnings
                self.unsummarised_errors = self.file_errors
                self._summarise(total_summary(self.results, len(done), self.settings.quantities))
            self.ended = {"FINISHED"} if done else {"CANCELLED"}
            if done and not self.errors and self.estimated:
                baking.learn_from_bake(self.estimated, time.monotonic() - self.started)
        # Blender keeps the last registered operators, and with them this session, for its redo
        # and history: keep nothing heavy (the jobs' geometry, the images' old pixels) past the end.
        self.run = None
        self.store = None
        self.results = []
        set_outcome(self.last_report)
        return self.ended

    def abandon(self):
        """Stop the worker without touching Blender data (Blender ends the operator: file loaded, ...)."""
        if self.run is not None:
            self.run.stop()
        _SESSIONS.discard(self)
        self.ended = {"CANCELLED"}

    # -- progress text -------------------------------------------------------------------------

    def _show_progress(self, context):
        i = min(int(self.fraction * len(self.run.jobs)), len(self.run.jobs) - 1)
        name = self.run.jobs[i].object_name
        self.set_texts(
            context,
            f"MC AO: baking {name} ({i + 1}/{len(self.run.jobs)}), {self.fraction:.0%} - Esc to cancel",
        )

    def set_texts(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        if self.area is not None:
            try:
                self.area.header_text_set(text)
            except ReferenceError:
                self.area = None


class OBJECT_OT_mc_ao_bake(bpy.types.Operator):
    bl_idname = "object.mc_ao_bake"
    bl_label = "Bake AO"
    # The tooltip. It documents the choices a user would otherwise have to guess.
    bl_description = (
        "Bake ambient occlusion of the selected meshes into one image each, with the scene's MC AO "
        "settings. An existing image of another size is resized to the bake's size. Objects that are "
        "not meshes or have no UV map are skipped. The baked image is packed into the .blend file "
        "(or, with Save to File, can load from its file). Esc cancels; a cancelled or failed bake "
        "leaves each image as it was. With Selected to Active, bakes the selected objects onto the "
        "active one"
    )
    # UNDO: a finished bake is one undo step, so Ctrl-Z takes back exactly the bake (its new images
    # go, a reused image gets its former size and settings) and not the step before it too, as it
    # would without one. Blender's undo keeps no pixels of an unpacked image whose datablock changed;
    # a finished bake's image is packed, so its pixels are in every later undo step and a redo brings
    # them back. Nothing is pushed for a cancelled or failed bake, which puts its images back itself
    # and changes no image datablock, so that later undo steps keep those images' pixels.
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        # A running bake does not disable the button: Blender 4.3 keeps drawing a button that was
        # disabled under a resting mouse pointer as disabled, and ignores clicks on it, after it
        # is enabled again. start() refuses a second bake instead, and the panel says why.
        reason = why_not(context)
        if reason is not None:
            cls.poll_message_set(reason)
            return False
        return True

    # -- running to the end (scripts, background mode) -------------------------------------------

    def execute(self, context):
        self.session = BakeSession(self.report)
        if not self.session.start(context, live=False):
            set_outcome(self.session.last_report)  # the refusal, not an earlier bake's success
            return {"CANCELLED"}
        return self.session.wait(context)

    # -- modal, from the UI ----------------------------------------------------------------------

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        self.session = BakeSession(self.report)
        if not self.session.start(context, live=True):
            set_outcome(self.session.last_report)  # the refusal, not an earlier bake's success
            return {"CANCELLED"}
        self.session.area = context.area
        wm = context.window_manager
        self.timer = wm.event_timer_add(TIMER_INTERVAL, window=context.window)
        wm.modal_handler_add(self)
        self.session.set_texts(context, "MC AO: starting the bake")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        try:
            result = self.session.on_event(context, event.type)
        except Exception as exc:  # a bug here must not leave the worker and the timer running
            result = self.session.fail(context, exc)
        if not result & {"RUNNING_MODAL", "PASS_THROUGH"}:
            self._remove_timer(context)
        return result

    def cancel(self, context):
        # Blender ends the operator without a modal event (file loaded, window closed, add-on
        # unregistered): stop the worker; the data it would restore may be gone, so leave it.
        self.session.abandon()
        self._remove_timer(context)
        try:
            context.window_manager.progress_end()
            self.session.set_texts(context, None)
            _redraw(context)
        except (AttributeError, ReferenceError, RuntimeError):
            pass

    def _remove_timer(self, context):
        if getattr(self, "timer", None) is not None:
            context.window_manager.event_timer_remove(self.timer)
            self.timer = None
