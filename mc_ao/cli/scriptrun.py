"""The script's side of one bake (mc_ao.service.Bake): progress, each object's outcome into the
summary, the --save file at the end, and the result table; the exit status."""

import sys
import time

from .. import interrupts, service, summaries
from ..outputs.store import Store
from ..terminal import escape
from . import table
from .blendsave import save_baked
from .progress import Progress
from .summary import parallel_record, s2a_record


class ScriptRun:
    """The script's side of one bake (mc_ao.service.Bake): progress on stderr, each object's outcome
    (its files written by the service, Ctrl-C held off meanwhile) into the summary and the table."""

    def __init__(self, plan, args, summary):
        import bpy

        self.plan, self.settings, self.args, self.summary = plan, plan.settings, args, summary
        store = None
        if plan.settings.vertex_colors and getattr(args, "save", None) is not None:
            # --save: the colour attributes go into the .blend file the run saves at its end
            store = Store(plan.settings, plan.folder, plan.files,
                          lambda kind, text: print(f"bake_ao: {escape(text)}", file=sys.stderr))
        self.run = service.Bake(plan, args.threads or None, live=False, store=store,
                                store_kinds={"color_attribute"}, blend=bpy.data.filepath, hold_interrupts=True,
                                store_after_save=True)
        self.progress = Progress(enabled=not args.quiet)
        self.rows, self.failed = [], set()
        # An object baked for two quantities (AO and thickness) is two jobs, one after the other, and
        # one object: counted, announced and shown progressing once.
        self.objects = list(dict.fromkeys(job.object_name for job in plan.jobs))
        self.quantities = {name: [job.quantity for job in plan.jobs if job.object_name == name]
                           for name in self.objects}

    def first_of_object(self, i):
        jobs = self.plan.jobs
        return i == 0 or jobs[i].object_name != jobs[i - 1].object_name

    def begin(self, i):
        jobs = self.plan.jobs
        if i < len(jobs) and self.first_of_object(i):
            name = jobs[i].object_name
            label = f"[{self.objects.index(name) + 1}/{len(self.objects)}] {escape(name)}"
            quantities = self.quantities[name]
            what = f" ({' and '.join(table.QUANTITY_WORDS.get(q, q) for q in quantities)})" if len(quantities) > 1 else ""
            print(f"bake_ao: {label.replace('] ', '] baking ', 1)}{what}", flush=True)
            self.progress.begin(label)

    def on_progress(self, i, fraction):
        if self.first_of_object(i):  # the object's first job bakes every quantity of it (core.bake_maps)
            self.progress.update(fraction)

    def on_outcome(self, outcome):
        self.progress.end()
        job, settings = outcome.job, self.settings
        name = escape(job.object_name)
        if outcome.trace:
            print(outcome.trace, file=sys.stderr, end="")
        result = outcome.result
        for note in outcome.notes:
            print(f"bake_ao: {name}: warning: {escape(note)}", file=sys.stderr)
        if result is not None and getattr(job, "atlas", False):
            from ..atlas import summary as atlas_summary

            print(f"bake_ao: {name}: {escape(atlas_summary(job, result))}", file=sys.stderr)
        if result is not None and getattr(job, "quantity", "ao") == "thickness" and outcome.baked:
            text = summaries.thickness_summary(settings, result).replace("set Distance", "set --max-distance")
            print(f"bake_ao: {name}: thickness map: {text}", file=sys.stderr)
        if result is not None and job.selected_to_active:
            print(f"bake_ao: {name}: from {', '.join(escape(h.name) for h in job.highpoly)}"
                  f"{summaries.miss_summary(result)}", file=sys.stderr)
        if not outcome.baked or outcome.file_error:
            error = outcome.error if not outcome.baked else service.not_written(outcome.file_error)
            if outcome.trace:
                error += "; the traceback is above"
            print(f"bake_ao: {name}: {escape(error)}", file=sys.stderr)
            self.failed.add(job.object_name)
            if result is None:
                seconds = time.monotonic() - self.run.started.get(outcome.index, time.monotonic())
                self.summary.add(job.object_name, "failed", seconds, error=error, **s2a_record(job))
            else:
                per_texel, _ = summaries.throughput(result)
                self.summary.add(job.object_name, "failed", result.seconds, result.rays, per_texel, outcome.files,
                                 error, **s2a_record(job, result))
        else:
            per_texel, _ = summaries.throughput(result)
            self.summary.add(job.object_name, "ok", result.seconds, result.rays, per_texel, outcome.files,
                             **s2a_record(job, result), **parallel_record(result))
            label = name if len(self.quantities[job.object_name]) == 1 else (
                f"{name}: {table.QUANTITY_WORDS.get(job.quantity, job.quantity)}")
            self.rows.append(table.row(label, result, settings, outcome.files))
        self.begin(outcome.index + 1)


def bake(plan, args, summary):
    """Bake the plan's jobs on a worker thread, each finished one's files written here; the exit status."""
    handler = ScriptRun(plan, args, summary)
    run, settings = handler.run, plan.settings
    try:
        handler.begin(0)
        run.start()
        while not run.handle(run.next_message(), handler):
            pass
    except BaseException as exc:
        run.stop()  # a "cancelled" message comes only from here: the cancel is this Ctrl-C's
        handler.progress.end()
        why = ("terminated (SIGTERM)" if isinstance(exc, interrupts.Terminated) else
               "cancelled (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else "the run stopped")
        for outcome in run.cancel_rest():
            summary.add(outcome.object_name, "failed", error=f"not baked: {why}")
        raise
    run.stop()
    rows, objects = handler.rows, handler.objects
    baked = [name for name in objects if name not in handler.failed]
    failures = len(objects) - len(baked)
    if getattr(args, "save", None) is not None and baked:
        if not save_baked(args.save, settings, [escape(name) for name in baked], summary):
            failures += 1
    table.show(rows)
    # A shared image (an atlas) is one job of several objects: the line counts its objects.
    members = {job.object_name: list(job.names) for job in plan.jobs if getattr(job, "atlas", False)}
    done = [n for name in baked for n in members.get(name, [name])]
    total = [n for name in objects for n in members.get(name, [name])]
    into = f" into {len(members)} image{'s' if len(members) != 1 else ''}" if members else ""
    print(f"bake_ao: baked {len(done)} of {len(total)} objects{into}" + (f", {failures} failed" if failures else ""))
    if failures and summary.error is None:
        summary.error = f"{failures} of {len(objects)} objects failed"
    return 1 if failures else 0

