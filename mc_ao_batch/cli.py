"""``scripts/bake_batch.py``: bake every .blend file of a manifest, one process per file.

Exit status: 0 when every task succeeded (or was already done), 1 when any task failed, 2 for a bad
manifest or bad arguments (nothing baked), 130 when interrupted (Ctrl-C), 143 when terminated (SIGTERM).
"""

import argparse
import os
import sys
import time
from pathlib import Path

from core._version import __version__
from mc_ao.interrupts import Terminated, sigterm_interrupts

from .manifest import BATCH_SUMMARY, ManifestError, plan
from .report import Progress, counts, older_text, output_problem, table, write_json_atomic
from .task import why_not_done

EPILOG = """\
engines:
  local      N processes at a time on this machine (default)
  dask       a Dask LocalCluster of N worker processes on 127.0.0.1, or --scheduler ADDRESS
  flamenco   write (--job-file) or submit (--manager URL) a Flamenco job of the tasks not done yet
  openjd     write the parameters of farm/openjd/mc_ao_bake.yaml (--job-params) for openjd run or
             a farm that runs Open Job Description (AWS Deadline Cloud)
"""


def default_workers():
    """As many as cores, at most 4: a bake's start (a process, importing Blender, opening the file)
    is serial, so two tasks overlap it with each other's baking (bench.batch: 2 workers bake 1.5
    times the assets per minute of 1 on 2 cores); past a few, each one's memory counts for more."""
    return max(1, min(os.cpu_count() or 1, 4))


#: Bytes of one bake process before its bake (the bpy 5.0 module with a small scene open: 421 MiB
#: resident, measured), what each task at a time costs beyond its bake's worker processes.
BYTES_PER_BAKE_PROCESS = 450 << 20


def batch_share(asked, cores=None, memory=None):
    """(tasks at a time, worker processes of each task's bake, why fewer than asked or None) on this
    machine: at most a task a core, each bake's processes sharing the cores its task has (tasks x
    processes x threads never above the cores: each process bakes on one thread), and every task's
    Blender and its bake's worker processes within 80% of the memory (core.execution.cost's process model; what
    a scene adds on top is each bake's own to check, as it does for its processes)."""
    from core import cost
    from core.base.machine import cpu_count, memory_limit

    cores = cpu_count() if cores is None else cores
    memory = memory_limit() if memory is None else memory
    tasks = max(1, min(int(asked), cores))
    processes = max(1, cores // tasks)
    why = []
    if tasks < asked:
        why.append(f"{cores} cores")
    if memory is not None:
        budget = 0.8 * memory

        def fits(n, k):
            return n * (BYTES_PER_BAKE_PROCESS + (k * cost.process_bytes(0) if k > 1 else 0)) <= budget

        fit = tasks
        while fit > 1 and not fits(fit, 1):
            fit -= 1
        each = max(1, cores // fit)
        while each > 1 and not fits(fit, each):
            each -= 1
        if fit < tasks or each < processes:
            why.append(f"memory for {fit} x {each} processes ({memory / 2 ** 30:.1f} GiB available)")
        tasks, processes = fit, each
    return tasks, processes, ", ".join(why) or None


def make_parser():
    p = argparse.ArgumentParser(
        prog="bake_batch.py", description="Bake AO of every .blend file in a manifest, one process per file.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("manifest", type=Path, help="the manifest (TOML): [defaults] and [[bake]] entries")
    p.add_argument("--output", "-o", type=Path, required=True,
                   help="output folder; each .blend file bakes into OUTPUT/<file stem>/")
    p.add_argument("--runner", choices=("local", "dask", "flamenco", "openjd"), default="local")
    p.add_argument("--workers", "-j", type=int, default=None,
                   help=f"tasks at a time (local, dask); default: the cores, at most 4 (here {default_workers()}); "
                        "at most the cores and what the memory holds, each task's bake on its share of the cores")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="dask: connect to this scheduler (tcp://host:8786) instead of starting a local cluster")
    p.add_argument("--force", action="store_true", help="bake every task, also those already done")
    p.add_argument("--rebake-older", action="store_true",
                   help="bake again the tasks whose files an older output version of mc_ao made (default: report "
                        "them and keep them; rebake_older = true in the manifest does the same per entry)")
    p.add_argument("--blender", default="auto", metavar="PATH|auto|bpy",
                   help="the Blender executable that bakes; auto (default): $BLENDER or blender on the "
                        "PATH, else the bpy module of this Python; bpy: the bpy module")
    p.add_argument("--summary", type=Path, metavar="PATH",
                   help=f"the batch's JSON summary (default: OUTPUT/{BATCH_SUMMARY}; none with --entry)")
    p.add_argument("--entry", type=int, metavar="N", help="run only the N-th [[bake]] entry (1-based)")
    p.add_argument("--verbose", "-v", action="store_true", help="also a line when a task starts")
    p.add_argument("--quiet", "-q", action="store_true", help="only failures and the table")
    farm = p.add_argument_group("farms")
    farm.add_argument("--manager", metavar="URL", help="flamenco: submit to this Manager (http://host:8080)")
    farm.add_argument("--job-file", type=Path, metavar="PATH", help="flamenco: write the job (JSON) here")
    farm.add_argument("--job-name", help="flamenco: the job's name (default: mc_ao bake <manifest>)")
    farm.add_argument("--farm-root", metavar="PATH",
                      help="flamenco, openjd: this mc_ao checkout as the farm's machines see it (default: here)")
    farm.add_argument("--job-params", type=Path, metavar="PATH", help="openjd: write the job parameters here")
    return p


def _blender_option(value):
    return None if value in (None, "", "auto") else value


def _fail(message, code=2):
    print(f"bake_batch: error: {message}", file=sys.stderr)
    return code


def main(argv=None):
    args = make_parser().parse_args(argv)
    if args.workers is not None and args.workers < 1:
        return _fail("--workers must be at least 1")
    if args.scheduler and args.runner != "dask":
        return _fail("--scheduler is for --runner dask")
    workers = args.workers or default_workers()
    threads, processes, clamped = 0, 0, None
    if args.runner == "local" or (args.runner == "dask" and not args.scheduler):
        # this machine runs the tasks: each gets its share of the cores, one thread a process
        asked = workers
        workers, processes, why = batch_share(asked)
        threads = 1
        if why is not None:
            clamped = f"--workers {asked}: {workers} tasks at a time ({why})"
    try:
        tasks = plan(args.manifest, args.output, threads=threads, processes=processes)
    except ManifestError as exc:
        return _fail(str(exc))
    if args.entry is not None:
        if not 1 <= args.entry <= len(tasks):
            return _fail(f"--entry {args.entry}: the manifest has entries 1 to {len(tasks)}")
        tasks = [tasks[args.entry - 1]]
    if args.rebake_older:
        for task in tasks:
            task.rebake_older = True

    summary_path = args.summary
    if summary_path is None and args.entry is None:
        summary_path = args.output / BATCH_SUMMARY
    inputs = [(args.manifest, "the manifest")] + [(t.blend, f"the .blend file of entry {t.index}") for t in tasks]
    inputs += [(p, f"a file of task {t.index}") for t in tasks for p in (t.summary, t.log)]
    if summary_path is not None and args.runner in ("local", "dask"):
        problem = output_problem(summary_path, inputs, replaces=("an mc_ao batch summary",))
        if problem is not None:
            return _fail(f"cannot write the batch summary {str(summary_path)!r}: {problem}; nothing was baked")

    if args.runner == "flamenco":
        return _flamenco(args, tasks, inputs)
    if args.runner == "openjd":
        return _openjd(args, tasks, inputs)

    if clamped is not None:
        print(f"bake_batch: {clamped}", file=sys.stderr, flush=True)
    blender = _blender_option(args.blender)
    if args.runner == "local" or not args.scheduler:
        from .task import NoBakerError, find_baker

        try:
            kind, exe = find_baker(blender)
        except NoBakerError as exc:
            return _fail(str(exc))
        if not args.quiet:
            how = f"Blender {exe}" if kind == "blender" else f"the bpy module of {exe}"
            each = f", {processes} processes each" if processes > 1 else ""
            print(f"bake_batch: {len(tasks)} tasks, {workers} at a time{each} ({args.runner}), baked by {how}",
                  flush=True)

    progress = Progress(len(tasks), verbose=args.verbose, quiet=args.quiet)
    start = time.monotonic()
    records, code = [], 0
    try:
        with sigterm_interrupts():  # SIGTERM stops the batch as Ctrl-C does: the summary says what finished
            records = _run(args, tasks, workers, progress, blender)
    except _Failed as exc:
        progress.close()
        return _fail(str(exc))
    except KeyboardInterrupt as exc:
        records = getattr(exc, "records", records)  # mc_ao_batch.runners.Interrupted: the finished tasks
        code = 143 if isinstance(exc, Terminated) or isinstance(exc.__context__, Terminated) else 130
    finally:
        progress.close()
    if code == 0:
        code = 1 if any(r["status"] == "failed" for r in records) else 0
    seconds = time.monotonic() - start

    if summary_path is not None:
        try:
            write_json_atomic(summary_path, {
                "mc_ao": __version__, "manifest": str(args.manifest.resolve()), "output": str(args.output.resolve()),
                "runner": args.runner, "workers": workers, **({"workers_asked": args.workers} if clamped else {}),
                "exit_code": code, "seconds": seconds,
                "counts": counts(records), "tasks": sorted(records, key=lambda r: r["index"]),
            }, inputs, replaces=("an mc_ao batch summary",))
        except OSError as exc:
            print(f"bake_batch: error: the batch summary was not written: {exc}", file=sys.stderr)
            summary_path = None
            code = code or 1
    if records:
        print(table(records))
    c = counts(records)
    line = f"bake_batch: {c['ok']} baked, {c['skipped']} already done, "
    if c["older"]:
        line += f"{older_text(c['older'])}, "
    line += f"{c['failed']} failed of {len(tasks)} in {seconds:.1f} s"
    if code in (130, 143):
        line += "; interrupted" if code == 130 else "; terminated (SIGTERM)"
    if summary_path is not None:
        line += f"; summary: {summary_path}"
    print(line, flush=True)
    return code


class _Failed(Exception):
    """The runner could not run (Dask not installed, no scheduler there): exit status 2, no summary."""


def _run(args, tasks, workers, progress, blender):
    """The tasks' records from the chosen runner."""
    if args.runner == "local":
        from .runners import run_local

        return run_local(tasks, workers=workers, progress=progress, force=args.force, blender=blender)
    from .runners import run_dask

    try:
        return run_dask(tasks, workers=workers, progress=progress, scheduler=args.scheduler, force=args.force,
                        blender=blender)
    except (RuntimeError, OSError) as exc:
        raise _Failed(str(exc)) from None


def _write_json(path, data, inputs, what):
    """A farm's JSON file (a job, job parameters); a message and False when it may not or cannot be written."""
    try:
        write_json_atomic(path, data, inputs)
    except OSError as exc:
        print(f"bake_batch: error: {what} was not written: {exc}", file=sys.stderr)
        return False
    return True


def _flamenco(args, tasks, inputs):
    from .farm import flamenco_job, submit_flamenco

    if not args.manager and not args.job_file:
        return _fail("--runner flamenco needs --manager URL (submit) or --job-file PATH (write)")
    name = args.job_name or f"mc_ao bake {args.manifest.stem}"
    job, skipped = flamenco_job(tasks, output=args.output.resolve(), name=name, mc_ao_root=args.farm_root,
                                force=args.force)
    todo = len(tasks) - len(skipped)
    older = sum(1 for t in skipped if why_not_done(t) is not None)  # skipped, not done: an older version's, kept
    print(f"bake_batch: {todo} tasks to bake, {len(skipped) - older} already done"
          + (f", {older_text(older)}" if older else ""))
    if args.job_file:
        if not _write_json(args.job_file, job, inputs, "the Flamenco job"):
            return 1
        print(f"bake_batch: Flamenco job written to {args.job_file}")
    if args.manager:
        if not todo:
            print("bake_batch: nothing to submit")
            return 0
        try:
            answer = submit_flamenco(job, args.manager)
        except RuntimeError as exc:
            return _fail(str(exc), 1)
        print(f"bake_batch: submitted job {answer.get('id', '?')} ({name}) to {args.manager}")
    return 0


def _openjd(args, tasks, inputs):
    from .farm import OPENJD_TEMPLATE, openjd_parameters

    if not args.job_params:
        return _fail("--runner openjd needs --job-params PATH")
    if args.entry is not None:
        return _fail("--entry is what each Open Job Description task runs; leave it out here")
    params = openjd_parameters(args.manifest, args.output, len(tasks), blender=args.blender,
                               mc_ao_root=args.farm_root)
    if not _write_json(args.job_params, params, inputs, "the job parameters"):
        return 1
    print(f"bake_batch: job parameters written to {args.job_params}; run the {len(tasks)} tasks with\n"
          f"  openjd run {OPENJD_TEMPLATE} -p file://{args.job_params.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
