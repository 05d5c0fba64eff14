"""A batch: its jobs run (in this process or on Dask), each job's outputs written by the client
as it arrives, then one summary — rows, ``summary.csv``, ``summary.json`` and ``index.html``.

Layout of the output folder::

    OUTDIR/<job>/<outputs>      the command's outputs (optimize: the program and report.html;
                                compare: report.html; calibrate: the twin file; simulate:
                                simulate.json), written atomically, once each
    OUTDIR/<job>/result.json    the job's record: status, error, the command's --json document
    OUTDIR/summary.csv|json     one row per job
    OUTDIR/index.html           the fleet's page: figures per machine, every job, failures
"""
from __future__ import annotations

import csv
import io
import json
import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

from ..errors import MtwinError
from ..io import write_bytes
from .job import Outcome
from .manifest import Job

OUTLIER = 0.25  # a fitted parameter this far (relative) from the fleet's median is marked
SUMMARY_FIELDS = ("job", "machine", "program", "twin", "measurement", "status", "cycle_before_s", "cycle_after_s",
                  "saved_s", "saved_pct", "measured_cycle_s", "cycle_error_pct", "fit_measure", "rms_before",
                  "rms_after", "holdout_error_pct", "error", "seconds", "worker")


@dataclass
class Batch:
    """A batch's result: the jobs, their outcomes (in the jobs' order), where it went."""

    command: str
    jobs: list
    outcomes: dict = field(default_factory=dict)  # job name -> Outcome
    out_dir: str = ""
    runner: str = ""
    seconds: float = 0.0
    interrupted: bool = False
    outlier = OUTLIER  # (the fleet table's mark, for the page)

    def fitted(self) -> dict:
        """calibrate: each machine's fitted parameters (job -> name -> value), the jobs that ran."""
        out = {}
        for j in self.jobs:
            o = self.outcomes.get(j.name)
            if o is not None and o.status == "ok" and isinstance(o.record, dict):
                out[j.name] = dict(o.record.get("params") or {})
        return out

    def fleet_table(self) -> list[dict]:
        """calibrate: per fitted parameter, each machine's value, its standard deviation and its
        ratio to the fleet's median (for three machines or more; ``odd`` when more than
        ``OUTLIER`` from it and more than two standard deviations: a difference the logs show,
        not one of a parameter they hardly see; ``at_least``: a limit no logged block of that
        machine reaches, set at the least its logs allow — a bound, never odd) — the one table
        the CSV, stderr and the page show."""
        fits = self.fitted()
        sd = {j.name: (self.outcomes[j.name].record.get("uncertainty") or {}) for j in self.jobs if j.name in fits}
        # limits no logged block of that machine reaches: the least value its logs allow, a bound
        low = {j.name: set(self.outcomes[j.name].record.get("unreached") or {}) for j in self.jobs if j.name in fits}
        out = []
        for k in sorted({k for p in fits.values() for k in p}):
            vals = [p[k] for p in fits.values() if k in p]
            med = statistics.median(vals) if len(vals) > 2 else None
            cells = {}
            for m, p in fits.items():
                if k in p:
                    r = p[k] / med if med else None
                    s = sd[m].get(k)
                    seen = s is None or abs(p[k] - med) > 2 * s if med else False
                    cells[m] = {"value": p[k], "sd": s, "ratio": r, "at_least": k in low[m],
                                "odd": r is not None and abs(r - 1) > OUTLIER and seen and k not in low[m]}
            out.append({"parameter": k, "machines": cells})
        return out

    def rows(self) -> list[dict]:
        return [summary_row(j, self.outcomes[j.name]) for j in self.jobs if j.name in self.outcomes]

    @property
    def counts(self) -> dict:
        c = {"ok": 0, "failed": 0, "refused": 0, "not run": 0}
        for j in self.jobs:
            c[self.outcomes[j.name].status if j.name in self.outcomes else "not run"] += 1
        return c

    @property
    def exit_code(self) -> int:
        if self.interrupted:
            return 130
        return 0 if self.counts["ok"] == len(self.jobs) else 1

    def summary(self) -> dict:
        rows = self.rows()
        saved = [r["saved_s"] for r in rows if r["saved_s"] is not None]
        before = [r["cycle_before_s"] for r in rows if r["saved_s"] is not None]
        machines = {}
        for r in rows:
            m = machines.setdefault(r["machine"], {"jobs": 0, "ok": 0, "cycle_before_s": None, "cycle_after_s": None,
                                                   "saved_s": None})
            m["jobs"] += 1
            if r["status"] == "ok":
                m["ok"] += 1
                if r["saved_s"] is not None:  # (optimize: the machine's cycle time before and after, saved)
                    for k in ("cycle_before_s", "cycle_after_s", "saved_s"):
                        m[k] = (m[k] or 0.0) + r[k]
        epoch = next((j.date_epoch for j in self.jobs if j.date_epoch is not None), None)
        return {"command": self.command, "jobs": len(self.jobs), **self.counts, "runner": self.runner,
                "source_date_epoch": epoch,
                "seconds": self.seconds, "interrupted": self.interrupted,
                "cycle_saved_s": sum(saved) if saved else None,
                "cycle_saved_pct": 100.0 * sum(saved) / sum(before) if before and sum(before) > 0 else None,
                "machines": machines}

    def as_dict(self) -> dict:
        """As ``mtwin batch … --json`` prints it."""
        jobs = []
        rows = {r["job"]: r for r in self.rows()}
        for j in self.jobs:
            o = self.outcomes.get(j.name)
            rec = o.record if o else {}
            if j.command == "calibrate" and isinstance(rec, dict):  # (a fit's before and after: its errors)
                rec = {"before": {"rms": (rec.get("steps") or [rec])[0].get("rms_before") or {}},
                       "after": {"rms": rec.get("rms_after") or {}}}
            jobs.append({"name": j.name, "program": j.program, "twin": j.twin, "measurement": j.measurement,
                         "status": o.status if o else "not run",
                         "outputs": {k: os.path.join(self.out_dir, j.name, n) for k, (n, _) in o.outputs.items()}
                         if o else {},
                         "before": rec.get("before", {}) if isinstance(rec, dict) else {},
                         "after": rec.get("after", {}) if isinstance(rec, dict) else {},
                         "figures": {k: rows[j.name][k] for k in SUMMARY_FIELDS[6:-3]
                                     if rows.get(j.name, {}).get(k) is not None},
                         "error": o.error if o else "", "seconds": o.seconds if o else None,
                         "worker": o.worker if o else ""})
        return {"jobs": jobs, "summary": self.summary()}


def run_batch(command: str, jobs: list[Job], out_dir: str, run: Callable, common: tuple = (), runner=None,
              on_done: Optional[Callable[[Outcome], None]] = None) -> Batch:
    """Run the jobs (``runner``: a :class:`~mtwin.fleet.runner.Cluster`, or None for one by one
    in this process) with ``run``, the command line in a process (``mtwin.cli.run_command``);
    write each one's outputs as it arrives, then the summary files.  Ctrl-C stops the batch:
    the jobs finished stay written, the summary says which did not run."""
    from .runner import run_serial

    b = Batch(command, jobs, out_dir=os.path.abspath(out_dir),
              runner=runner.describe() if runner is not None else "in this process, one job at a time")
    os.makedirs(out_dir, exist_ok=True)
    t0 = time.perf_counter()

    def done(o: Outcome) -> None:
        if o.name in b.outcomes:  # (a task delivered twice is written once)
            return
        write_outcome(b.out_dir, o)
        b.outcomes[o.name] = o
        if on_done is not None:
            on_done(o)

    try:
        if runner is None:
            run_serial(jobs, common, done, run)
        else:
            runner.run(jobs, common, done, run)
    except KeyboardInterrupt:
        b.interrupted = True
    b.seconds = time.perf_counter() - t0
    write_summary(b)
    return b


def write_outcome(out_dir: str, o: Outcome) -> None:
    d = os.path.join(out_dir, o.name)
    os.makedirs(d, exist_ok=True)
    for name, data in o.outputs.values():
        write_bytes(data, os.path.join(d, name))
    rec = {"job": o.name, "status": o.status, "error": o.error, "exit_code": o.exit_code, "seconds": o.seconds,
           "worker": o.worker, "result": o.record, "log": o.log}
    write_bytes((json.dumps(rec, indent=1) + "\n").encode(), os.path.join(d, "result.json"))


def write_summary(b: Batch) -> None:
    from ..report.fleet_html import fleet_html

    rows = b.rows()
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k]))
                    for k in SUMMARY_FIELDS})
    write_bytes(buf.getvalue().encode(), os.path.join(b.out_dir, "summary.csv"))
    write_bytes((json.dumps(b.as_dict(), indent=1) + "\n").encode(), os.path.join(b.out_dir, "summary.json"))
    if b.command == "calibrate":
        write_bytes(parameters_csv(b).encode(), os.path.join(b.out_dir, "parameters.csv"))
    write_bytes(fleet_html(b), os.path.join(b.out_dir, "index.html"))


def parameters_csv(b: Batch) -> str:
    """The fleet table: a row per machine, its fitted parameters, held-out cycle-time error."""
    table = b.fleet_table()
    held = {r["job"]: r["holdout_error_pct"] for r in b.rows()}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["machine", *(c for t in table for c in (t["parameter"], f"{t['parameter']}_sd")),
                "holdout_cycle_error_pct", "at_least"])
    num = (lambda v, fmt: "" if v is None else format(v, fmt))
    for m in b.fitted():
        cells = [t["machines"].get(m, {}) for t in table]
        # at_least: the limits no logged block of the machine reaches, each the least value allowed
        low = ";".join(t["parameter"] for t, x in zip(table, cells) if x.get("at_least"))
        w.writerow([m, *(c for x in cells for c in (num(x.get("value"), ".6g"), num(x.get("sd"), ".3g"))),
                    num(held.get(m), ".6g"), low])
    return buf.getvalue()


def summary_row(j: Job, o: Outcome) -> dict:
    """One job's figures, by command (docs/fleet.md): optimize — the cycle time before and
    after, saved; simulate — the cycle time (``cycle_before_s``: the program as written);
    compare — the twin's cycle time, the measured one and the error in %; calibrate — the fit's
    error before and after (``fit_measure``: the block-time windows of a timing fit, or the
    signal the fit improved most) and the held-out cycle-time error in %."""
    rec = o.record if isinstance(o.record, dict) else {}
    row = {k: None for k in ("cycle_before_s", "cycle_after_s", "measured_cycle_s", "cycle_error_pct",
                             "fit_measure", "rms_before", "rms_after", "holdout_error_pct")}
    if o.status == "ok" and j.command == "optimize":
        row["cycle_before_s"] = rec.get("before", {}).get("cycle_time")
        row["cycle_after_s"] = rec.get("after", {}).get("cycle_time")
    elif o.status == "ok" and j.command == "simulate":
        row["cycle_before_s"] = rec.get("cycle_time")
    elif o.status == "ok" and j.command == "compare":
        ct = rec.get("cycle_time") or {}
        row["cycle_before_s"], row["measured_cycle_s"] = ct.get("simulated"), ct.get("measured")
        row["cycle_error_pct"] = _pct(ct.get("relative_error"))
    elif o.status == "ok" and j.command == "calibrate":
        first = (rec.get("steps") or [rec])[0]
        row["fit_measure"], row["rms_before"], row["rms_after"] = _fit_error(first.get("rms_before"),
                                                                            rec.get("rms_after"))
        held = [h["cycle_time"].get("relative_error") for h in rec.get("holdout", []) if h.get("cycle_time")]
        row["holdout_error_pct"] = _pct(max(held, key=abs)) if held else None
    b, a = row["cycle_before_s"], row["cycle_after_s"]
    saved = b - a if b is not None and a is not None else None
    machine = j.name if j.command == "calibrate" else j.machine  # (a calibration's rows are named per machine)
    return {"job": j.name, "machine": machine, "program": j.program, "twin": j.twin or "",
            "measurement": j.measurement or "", "status": o.status, **row, "saved_s": saved,
            "saved_pct": 100.0 * saved / b if saved is not None and b else None, "error": o.error,
            "seconds": o.seconds, "worker": o.worker, "outputs": {k: f"{j.name}/{n}" for k, (n, _) in o.outputs.items()}}


def _pct(x):
    return None if x is None else 100.0 * x


def _fit_error(before, after):
    """(what, before, after): a fit's error as one pair — the value of a single measure (the
    block-time windows of a timing fit), else the signal whose RMS the fit lowered most."""
    if not (isinstance(before, dict) and isinstance(after, dict)):
        return None, None, None
    both = [k for k in before if isinstance(before[k], (int, float)) and isinstance(after.get(k), (int, float))]
    if not both:
        return None, None, None
    k = min(both, key=lambda n: after[n] / before[n] if before[n] else 1.0)
    return k, float(before[k]), float(after[k])


def check_out_dir(output: str, jobs=(), others=()) -> None:
    """The output folder: a folder (made) or a name not yet taken, in a folder that exists, and
    none of the batch's inputs inside it — each job's folder there is written whole (a job
    named ``j`` whose program is ``j/ga.nc`` beside the manifest would be replaced by its
    optimised self), and the summary files beside them."""
    p = Path(output)
    if p.exists() and not p.is_dir():
        raise MtwinError(f"-o {output}: a file, not a folder")
    if not p.exists() and not p.resolve().parent.is_dir():
        raise MtwinError(f"-o {output}: the folder {p.resolve().parent} does not exist")
    if not p.exists():
        return
    root = p.resolve()
    inputs = [Path(j.base, f) for j in jobs for f in j.files()] + [Path(x) for x in others if x]
    for f in inputs:
        if f.resolve().is_relative_to(root):
            raise MtwinError(f"-o {output}: the output folder holds an input of the batch ({f}); its job folders "
                             f"and summary files would be written over it — give another -o folder")
