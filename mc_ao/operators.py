"""The Bake AO operator: modal with a worker thread from the UI, synchronous from scripts and -b.

One bake is a list of jobs (one per selected mesh) run one after another by core.bake_ao on a worker
thread. The thread never touches bpy: it only puts messages (progress, finished tiles, results,
errors) on a queue, which the main thread drains, from a window-manager timer when modal or in a
blocking loop when not, and applies to Blender's images.
"""

import os
import queue
import threading
import time
import traceback

import bpy
import numpy as np

from . import baking, corelink, images
from .extract import ExtractError
from .properties import resolve_threads
from .settings import BakeSettings

# Bakes in flight, so that unregister() can stop their threads.
_RUNS = set()
# Seconds between two live updates of an image: writing a large image's pixels takes milliseconds.
LIVE_UPDATE_INTERVAL = 0.25
TIMER_INTERVAL = 0.1
# Live updates keep an RGBA float copy of the image (16 bytes a texel): beyond 4096 x 4096 (256 MiB)
# the image is written once, at the end.
LIVE_MAX_TEXELS = 4096 * 4096


class BakeRun:
    """Runs the jobs one after another on a worker thread and reports through ``messages``.

    Messages are tuples: ("progress", job, fraction), ("tile", job, rows, cols, block),
    ("done", job, result), ("cancelled", job), ("error", job, exception),
    ("crash", job, exception, traceback text), and ("end",) last.
    """

    def __init__(self, jobs, settings, threads, live):
        self.jobs = jobs
        self.settings = settings
        self.threads = threads
        self.live = live
        self.cancel = threading.Event()
        self.messages = queue.SimpleQueue()
        # Imported here, in the main thread, so that the worker finds it loaded.
        self.core = corelink.load()
        self.thread = threading.Thread(target=self._work, name="mc_ao bake", daemon=True)

    def start(self):
        _RUNS.add(self)
        self.thread.start()

    def stop(self):
        """Cancel the bake and wait for the worker to finish (it checks the cancel event often)."""
        self.cancel.set()
        if self.thread.is_alive():
            self.thread.join()
        _RUNS.discard(self)

    def _work(self):
        put = self.messages.put
        for i, job in enumerate(self.jobs):
            if self.cancel.is_set():
                put(("cancelled", i))
                break

            def progress(fraction, i=i):
                put(("progress", i, fraction))

            def on_tile(rows, cols, block, i=i):
                put(("tile", i, rows, cols, np.array(block, dtype=np.float32)))

            try:
                result = job.run(
                    self.settings, self.threads, progress=progress, cancel=self.cancel,
                    on_tile=on_tile if self.live else None,
                )
            except self.core.BakeCancelled:
                put(("cancelled", i))
                break
            except self.core.McAoError as exc:
                put(("error", i, exc))
                break
            except Exception as exc:  # a bug, or the machine out of memory: report it, keep the trace
                put(("crash", i, exc, traceback.format_exc()))
                break
            put(("done", i, result))
        put(("end",))


def _output_dir(settings):
    """Absolute folder for saved files, or raise ExtractError when "//" has no .blend file to refer to."""
    if settings.output_dir.startswith("//") and not bpy.data.filepath:
        raise ExtractError(
            f"the output folder {settings.output_dir!r} is relative to the .blend file, "
            "which is not saved yet; save it or choose an absolute folder"
        )
    return bpy.path.abspath(settings.output_dir)


def _redraw(context):
    """Redraw the editors that show images or the panel: Blender redraws them on events only."""
    if context.window_manager is None:
        return
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in {"IMAGE_EDITOR", "VIEW_3D"}:
                area.tag_redraw()


def is_running():
    """Whether an AO bake is in progress (the panel says so, the operator refuses a second one)."""
    return bool(_RUNS)


def summary(job, result):
    """One line per baked object: size, time, samples per texel, ray throughput."""
    h, w = result.ao.shape
    per_texel, rate = baking.throughput(result)
    return (
        f"{job.object_name}: {w}x{h} into {job.image_name!r} in {result.seconds:.2f} s, "
        f"{per_texel:.0f} samples per texel, {rate:.2f} M rays/s"
    )


class OBJECT_OT_mc_ao_bake(bpy.types.Operator):
    """Bake ambient occlusion of the selected meshes into images, with the scene's MC AO settings"""

    bl_idname = "object.mc_ao_bake"
    bl_label = "Bake AO"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        # A running bake does not disable the button: Blender 4.3 keeps drawing a button that was
        # disabled under a resting mouse pointer as disabled, and ignores clicks on it, after it
        # is enabled again. _start() refuses a second bake instead, and the panel says why.
        reason = baking.why_not_bakeable(context.selected_objects)
        if reason is not None:
            cls.poll_message_set(reason)
            return False
        return True

    # -- setting up ---------------------------------------------------------------------------

    def _start(self, context, live):
        """Plan the jobs and start the worker; False (after reporting) when there is nothing to do."""
        if is_running():
            self.report({"WARNING"}, "An AO bake is already running; Esc cancels it")
            return False
        missing = corelink.missing_dependency()
        if missing is not None:
            self.report({"ERROR"}, f"Cannot bake: {missing}")
            return False
        self.settings = BakeSettings.from_properties(context.scene.mc_ao)
        self.errors = 0
        self.finished = []
        self.images = {}  # job index -> (image, Snapshot, live pixel buffer or None)
        self.pending = set()  # jobs whose live buffer has tiles not yet in the image
        self.last_flush = 0.0
        self.fraction = 0.0
        selected = context.selected_objects
        targets = baking.targets_of(selected)
        for obj in selected:
            if obj.type == "MESH" and obj not in targets:
                self.report({"WARNING"}, f"{obj.name}: skipped, it has no UV map")
        try:
            self.output_dir = _output_dir(self.settings) if self.settings.save_to_file else None
            jobs = baking.plan(
                context.evaluated_depsgraph_get(), targets, self.settings,
                selected=selected, view_layer=context.view_layer,
            )
        except (ExtractError, corelink.load().McAoError) as exc:
            self.report({"ERROR"}, str(exc))
            return False
        if not jobs:
            self.report({"ERROR"}, "Nothing to bake: select a mesh with a UV map")
            return False
        w, h = self.settings.size
        live = live and w * h <= LIVE_MAX_TEXELS
        self.run = BakeRun(jobs, self.settings, resolve_threads(context, self.settings), live)
        self.run.start()
        context.window_manager.progress_begin(0.0, 1.0)
        return True

    # -- the main-thread side of the messages ---------------------------------------------------

    def _image(self, i):
        """The image of job i, prepared (created, resized) on first use; its live buffer if live."""
        if i not in self.images:
            job = self.run.jobs[i]
            w, h = self.settings.size
            image, snapshot = images.prepare_image(job.image_name, w, h, self.settings.float_buffer)
            buffer = images.pixels_of(image) if self.run.live else None
            self.images[i] = (image, snapshot, buffer)
        return self.images[i]

    def _handle(self, context, message):
        """Apply one worker message; return True at the end of the run."""
        kind, *args = message
        if kind == "progress":
            i, fraction = args
            self.fraction = (i + fraction) / len(self.run.jobs)
            context.window_manager.progress_update(self.fraction)
        elif kind == "tile":
            i, rows, cols, block = args
            try:
                _, _, buffer = self._image(i)
            except images.ImageError:
                return False  # reported when the job is done
            buffer[rows, cols] = images.rgba(block, buffer.shape[2])
            self.pending.add(i)
        elif kind == "done":
            self._finish_job(context, *args)
        elif kind == "error":
            i, exc = args
            self.errors += 1
            self.report({"ERROR"}, f"{self.run.jobs[i].object_name}: {exc}")
        elif kind == "crash":
            i, exc, trace = args
            self.errors += 1
            print(trace)
            self.report(
                {"ERROR"},
                f"{self.run.jobs[i].object_name}: bake failed ({type(exc).__name__}: {exc}); see the console",
            )
        elif kind == "end":
            return True
        return False

    def _finish_job(self, context, i, result):
        job = self.run.jobs[i]
        self.pending.discard(i)
        try:
            image, _, _ = self._image(i)
        except images.ImageError as exc:
            self.errors += 1
            self.report({"ERROR"}, f"{job.object_name}: {exc}")
            return
        images.set_pixels(image, images.rgba(result.ao, image.channels))
        _redraw(context)
        self.finished.append(i)
        self.report({"INFO"}, summary(job, result))
        for note in baking.input_notes(result):
            self.report({"WARNING"}, f"{job.object_name}: {note}")
        if self.output_dir is not None:
            path = os.path.join(self.output_dir, self.settings.file_name_for(job.object_name))
            metadata = {"object": job.object_name, "blend": bpy.path.basename(bpy.data.filepath)}
            try:
                how = images.save(result, path, self.settings, metadata)
            except (corelink.load().McAoError, OSError, RuntimeError) as exc:
                self.errors += 1
                self.report({"ERROR"}, f"{job.object_name}: could not save {path}: {exc}")
            else:
                self.report({"INFO"}, f"{job.object_name}: saved {path} ({how})")

    def _flush_live(self, context):
        now = time.monotonic()
        if not self.pending or now - self.last_flush < LIVE_UPDATE_INTERVAL:
            return
        for i in self.pending:
            image, _, buffer = self.images[i]
            images.set_pixels(image, buffer)
        self.pending.clear()
        self.last_flush = now
        _redraw(context)

    def _restore_unfinished(self):
        """Put back the images of jobs that did not finish: a cancelled bake leaves no partial image."""
        for i, (_, snapshot, _) in self.images.items():
            if i not in self.finished:
                snapshot.restore()

    def _end(self, context, cancelled=False):
        self.run.stop()
        if cancelled or self.errors:
            self._restore_unfinished()
        context.window_manager.progress_end()
        self._set_texts(context, None)
        _redraw(context)  # restored images, and the panel without its "Baking" line
        if cancelled:
            kept = [self.run.jobs[i].object_name for i in self.finished]
            note = f"; kept the finished bakes of {', '.join(kept)}" if kept else ""
            self.report({"WARNING"}, f"AO bake cancelled{note}")
            return {"CANCELLED"}
        return {"CANCELLED"} if self.errors else {"FINISHED"}

    # -- running to the end (scripts, background mode) -------------------------------------------

    def execute(self, context):
        if not self._start(context, live=False):
            return {"CANCELLED"}
        try:
            while not self._handle(context, self.run.messages.get()):
                pass
        except KeyboardInterrupt:
            return self._end(context, cancelled=True)
        return self._end(context)

    # -- modal, from the UI ----------------------------------------------------------------------

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        if not self._start(context, live=True):
            return {"CANCELLED"}
        self.area = context.area
        wm = context.window_manager
        self.timer = wm.event_timer_add(TIMER_INTERVAL, window=context.window)
        wm.modal_handler_add(self)
        self._set_texts(context, "MC AO: starting the bake")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        try:
            return self._modal(context, event)
        except Exception as exc:  # a bug here must not leave the worker and the timer running
            traceback.print_exc()
            self.report({"ERROR"}, f"AO bake stopped by an internal error ({type(exc).__name__}: {exc}); see the console")
            self._remove_timer(context)
            self._end(context, cancelled=True)
            return {"CANCELLED"}

    def _modal(self, context, event):
        if event.type == "ESC":
            self._remove_timer(context)
            return self._end(context, cancelled=True)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        ended = False
        while not ended:
            try:
                ended = self._handle(context, self.run.messages.get_nowait())
            except queue.Empty:
                break
        if ended:
            self._remove_timer(context)
            return self._end(context)
        self._flush_live(context)
        self._show_progress(context)
        return {"PASS_THROUGH"}

    def cancel(self, context):
        # Blender ends the operator without a modal event (file loaded, window closed, add-on
        # unregistered): stop the worker; the data it would restore may be gone, so leave it.
        self.run.stop()
        self._remove_timer(context)
        try:
            context.window_manager.progress_end()
            self._set_texts(context, None)
            _redraw(context)
        except (AttributeError, ReferenceError, RuntimeError):
            pass

    def _remove_timer(self, context):
        if getattr(self, "timer", None) is not None:
            context.window_manager.event_timer_remove(self.timer)
            self.timer = None

    def _show_progress(self, context):
        i = min(int(self.fraction * len(self.run.jobs)), len(self.run.jobs) - 1)
        name = self.run.jobs[i].object_name
        self._set_texts(
            context,
            f"MC AO: baking {name} ({i + 1}/{len(self.run.jobs)}), {self.fraction:.0%} - Esc to cancel",
        )

    def _set_texts(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        area = getattr(self, "area", None)
        if area is not None:
            try:
                area.header_text_set(text)
            except ReferenceError:
                self.area = None
