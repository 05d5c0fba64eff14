"""One batch job, run where it is sent: a pure function of (the job, its input files' bytes,
the batch's common options) → (its output files' bytes, its record).

The job *is* the command a user would type — ``mtwin optimize PROGRAM --twin T -o … --report …
--json`` — run in this process through the same command-line code (handed in as ``run``: the
command line sits above this package), with its stdout and stderr captured and its outputs
written to a private folder and read back.  So a batch job's outputs
are the single command's, byte for byte, by construction, and every option of the command is
a batch option too.

Where the worker sees the client's files (one machine, or a shared file system) the job runs
in the client's folder; elsewhere the files that travelled with the task are written to a
private folder with the same relative layout and the job runs there (a path written as an
absolute one is then named as the worker's copy in the outputs).  Nothing is shared between
jobs: the private folders are removed, the working directory is given back.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .manifest import Job

# one job at a time per process: a job sets the working directory (and the command line it
# runs, sys.stdout/stderr)
_LOCK = threading.Lock()


@dataclass
class Outcome:
    """What a job gives back: its status, outputs (key -> (file name, bytes)), its record."""

    name: str
    status: str  # ok | failed | refused
    outputs: dict = field(default_factory=dict)
    record: dict = field(default_factory=dict)  # the command's --json document
    error: str = ""
    log: str = ""  # the command's stderr
    seconds: float = 0.0
    worker: str = ""
    exit_code: int = 0


def read_inputs(job: Job) -> dict:
    """The job's input files' bytes, by the path as written (what travels with the task)."""
    return {p: Path(job.base, p).read_bytes() for p in job.files()}


def outputs_of(job: Job, out: str) -> tuple[list[str], dict]:
    """The arguments that send the command's outputs into ``out``, and what each output is."""
    stem = Path(job.program).name
    if job.command == "optimize":
        files = {"program": stem, "report": "report.html"}
        return ["-o", os.path.join(out, files["program"]), "--report", os.path.join(out, "report.html")], files
    if job.command == "compare":
        return ["--report", os.path.join(out, "report.html")], {"report": "report.html"}
    if job.command == "calibrate":
        name = f"{Path(job.twin).stem if job.twin else 'twin'}.toml"
        return ["-o", os.path.join(out, name)], {"twin": name}
    return [], {}


def arguments(job: Job, common: tuple, out: str) -> tuple[list[str], dict]:
    """The command line of the job (without ``mtwin``), and its output files."""
    args = [job.command, job.program]
    if job.measurement:
        args.append(job.measurement)
    outs, files = outputs_of(job, out)
    args += outs + ["--json"]
    if job.twin:
        args += ["--twin", job.twin]
    return args + list(common) + list(job.options), files


def run_job(job: Job, inputs: dict, common: tuple, run: Callable) -> Outcome:
    """Run the job here (see the module's doc) with ``run(args) -> (exit code, stdout,
    stderr)``, the mtwin command line in this process (``mtwin.cli.run_command``); never
    raises for the job's own failure."""
    import socket

    t0 = time.perf_counter()
    with _LOCK, _workdir(job, inputs) as (where, tmp), _epoch(job.date_epoch):
        out = os.path.join(tmp, "out")
        os.mkdir(out)
        staged = where != job.base
        j = job if not staged else _relocated(job, where)
        if job.command == "calibrate":
            code, record, stderr, files = _procedure(j, common, out, run)
        else:
            args, files = arguments(j, common, out)
            code, stdout, stderr = run(args)
            record = _json(stdout)
        outputs = {k: (name, Path(out, name).read_bytes()) for k, name in files.items()
                   if code == 0 and os.path.isfile(os.path.join(out, name))}
        record = _named(record, out)
        if job.command == "simulate" and code == 0:
            outputs["summary"] = ("simulate.json", stdout.encode())
    if code == 130:  # Ctrl-C in this process (the command mapped it): the batch stops, not this job only
        raise KeyboardInterrupt
    status, error = _status(job, code, record, stderr)
    return Outcome(job.name, status, outputs, record, error, stderr, time.perf_counter() - t0,
                   f"{socket.gethostname()}:{os.getpid()}", code)


def _procedure(job: Job, common: tuple, out: str, run: Callable):
    """calibrate: the procedure's steps in turn (each from the twin file the step before wrote;
    one step of the job's options when there are none), then the calibrated twin compared with
    each held-out log.  (exit code, record, stderr, outputs)"""
    _, files = outputs_of(job, out)
    final = os.path.join(out, files["twin"])
    steps = job.steps or ((),)
    twin, logs, records = job.twin, [], []
    more = [p for pair in job.pairs for p in pair]
    for k, opts in enumerate(steps, start=1):
        dst = final if k == len(steps) else os.path.join(out, f"step{k}.toml")
        args = ["calibrate", job.program, job.measurement, *more, "-o", dst, "--json"]
        args += (["--twin", twin] if twin else []) + list(common) + list(job.options) + list(opts)
        code, stdout, stderr = run(args)
        logs.append(stderr)
        rec = _json(stdout)
        records.append(rec)
        if code != 0:
            return code, {"steps": records}, "".join(logs), files
        twin = dst
    record = {**records[-1], "steps": records, "holdout": []}
    for prog, meas in job.holdout:
        code, stdout, stderr = run(["compare", prog, meas, "--json", "--twin", final, *job.compare_options])
        logs.append(stderr)
        if code != 0:
            return code, record, "".join(logs), files
        c = _json(stdout)
        record["holdout"].append({"program": prog, "measurement": meas, "cycle_time": c.get("cycle_time"),
                                  "blocks": c.get("blocks")})
    return 0, record, "".join(logs), files


def _named(doc, out: str):
    """The record with the private folder's paths as the output's own names (the folder is gone
    when the record is read)."""
    if isinstance(doc, dict):
        return {k: _named(v, out) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_named(v, out) for v in doc]
    if isinstance(doc, str) and doc.startswith(out + os.sep):
        return doc[len(out) + 1:]
    return doc


def _status(job: Job, code: int, record, stderr: str) -> tuple[str, str]:
    if code == 0:
        return "ok", ""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    said = next((ln for ln in reversed(lines) if ln.startswith(("error:", "internal error:"))), None)
    said = said or (lines[-1] if lines else f"exit code {code}")
    said = said.split(":", 1)[1].strip() if said.startswith(("error:", "internal error:")) else said
    refused = job.command == "optimize" and isinstance(record, dict) and record.get("written") is False
    return ("refused" if refused else "failed"), said


def _json(text: str):
    try:
        return json.loads(text) if text.strip() else {}
    except ValueError:
        return {}


@contextlib.contextmanager
def _epoch(epoch):
    """``SOURCE_DATE_EPOCH`` set to the batch's start for the job (the date a calibrated twin
    file's journal entry carries), given back after."""
    if epoch is None:
        yield
        return
    old = os.environ.get("SOURCE_DATE_EPOCH")
    os.environ["SOURCE_DATE_EPOCH"] = str(int(epoch))
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("SOURCE_DATE_EPOCH", None)
        else:
            os.environ["SOURCE_DATE_EPOCH"] = old


@contextlib.contextmanager
def _workdir(job: Job, inputs: dict):
    """(the folder the job runs in, a private scratch folder), the working directory set to
    the first; the client's folder where its files are here as they were sent, else a copy."""
    here = os.getcwd()
    tmp = tempfile.mkdtemp(prefix="mtwin-job-")
    try:
        where = job.base if _same_files(job.base, inputs) else _stage(os.path.join(tmp, "in"), inputs)
        os.chdir(where)
        yield where, tmp
    finally:
        os.chdir(here)
        shutil.rmtree(tmp, ignore_errors=True)


def _same_files(base: str, inputs: dict) -> bool:
    try:
        return all(Path(base, p).read_bytes() == b for p, b in inputs.items())
    except OSError:
        return False


def _stage(root: str, inputs: dict) -> str:
    for p, data in inputs.items():
        dst = Path(root, _staged_name(p))
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_bytes(data)
    return root


def _staged_name(p: str) -> str:
    # a relative path keeps its place under the copy; an absolute one (or one climbing out
    # with ..) is put under _abs/ — the job then names the copy
    q = os.path.normpath(p)
    return p if not (os.path.isabs(q) or q.startswith("..")) else os.path.join("_abs", q.lstrip(os.sep).replace("..", "__"))


def _relocated(job: Job, where: str) -> Job:
    from dataclasses import replace

    m = (lambda p: _staged_name(p) if p else p)
    return replace(job, program=m(job.program), twin=m(job.twin), measurement=m(job.measurement), base=where,
                   pairs=tuple((m(a), m(b)) for a, b in job.pairs), holdout=tuple((m(a), m(b)) for a, b in job.holdout))
