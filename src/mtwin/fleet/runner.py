"""Where a batch's jobs run: one by one in this process, or on Dask — a local cluster of one
single-threaded worker process per core, or an existing cluster by its scheduler's address.

The client reads each job's input files and sends them with the task; the worker runs
:func:`~mtwin.fleet.job.run_job` and sends the outputs back; ``on_done`` (the client) writes
them as results arrive (``as_completed``), so workers need no shared file system and nothing
is written twice.  A bounded number of tasks is in flight at a time (four per worker thread):
the client holds few programs in memory, and Ctrl-C cancels little.
"""
from __future__ import annotations

import logging
import os
from typing import Callable, Optional

from ..errors import MtwinError
from .job import Outcome, read_inputs, run_job
from .manifest import Job

FLEET_HINT = "pip install 'mtwin[fleet]'"
IN_FLIGHT_PER_THREAD = 4
# the environment of a local cluster's workers: one numba thread each (the worker is the unit
# of parallelism), and no background compile (the first task warms the worker's cache)
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "MTWIN_BACKGROUND_COMPILE": "0", "OMP_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
_WARM = {}


def cores() -> int:
    """The cores this process may use (a container's or a job scheduler's share, not the host's)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _size(job: Job) -> int:
    try:
        return sum(os.path.getsize(os.path.join(job.base, p)) for p in job.files() if p != job.twin)
    except OSError:
        return 0


def _check_scheduler_file(path: str) -> None:
    """A scheduler file that is there and names an address (Dask would wait for it forever)."""
    import json

    try:
        with open(path, encoding="utf-8") as fh:
            address = json.load(fh).get("address")
    except OSError as exc:
        raise MtwinError(f"--scheduler-file {path}: {exc.strerror or exc}") from None
    except (ValueError, AttributeError):
        raise MtwinError(f"--scheduler-file {path}: not a Dask scheduler file (JSON with an address)") from None
    if not isinstance(address, str):
        raise MtwinError(f"--scheduler-file {path}: no scheduler address in it")


def have_dask() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def run_serial(jobs: list[Job], common: tuple, on_done: Callable[[Outcome], None], run: Callable) -> None:
    """Each job in turn in this process (what batch does without Dask, or with --workers 0)."""
    for job in jobs:
        on_done(run_job(job, read_inputs(job), common, run))


def warmed_job(job: Job, inputs: dict, common: tuple, run: Callable) -> Outcome:
    """A job on a worker: the worker's kernel cache is warmed by its first task (compiled
    kernels loaded, or compiled once into the worker's cache), then the job runs."""
    if not _WARM:
        import sys

        os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # (read when numba is imported)
        if "numba" in sys.modules:  # (a worker that imported it already: one thread from now on)
            sys.modules["numba"].set_num_threads(1)
        from ..warmup import warm

        warm()
        _WARM["done"] = True
    return run_job(job, inputs, common, run)


SCHEDULER_TIMEOUT = 30.0  # s: a scheduler that does not complete the handshake by then is given up


def _scheduler_timeout() -> float:
    """SCHEDULER_TIMEOUT, or MTWIN_SCHEDULER_TIMEOUT (s) where set: a slow link may need more."""
    import os

    try:
        v = float(os.environ.get("MTWIN_SCHEDULER_TIMEOUT", SCHEDULER_TIMEOUT))
    except ValueError:
        v = SCHEDULER_TIMEOUT
    return v if 0 < v < 3600 else SCHEDULER_TIMEOUT


def _client_within(make, seconds: float):
    """``make()`` (a Dask client), or TimeoutError after ``seconds``: Dask's own connect timeout
    covers the TCP connection, not a peer that accepts it and never answers (the handshake then
    waits for ever).  The attempt runs in a daemon thread, left behind if it hangs."""
    import threading

    box: dict = {}

    def attempt():
        try:
            box["client"] = make()
        except BaseException as exc:  # noqa: BLE001 (handed to the caller)
            box["error"] = exc

    th = threading.Thread(target=attempt, daemon=True, name="mtwin-dask-connect")
    th.start()
    th.join(seconds)
    if th.is_alive():
        raise TimeoutError(f"no answer within {seconds:g} s (an address that accepts connections but is no Dask "
                           f"scheduler?)")
    if "error" in box:
        raise box["error"]
    return box["client"]


class Cluster:
    """A Dask client on a local cluster (``workers`` processes) or on a scheduler's address /
    scheduler file; refuses, before any job runs, a scheduler it cannot reach."""

    def __init__(self, workers: Optional[int] = None, scheduler: Optional[str] = None,
                 scheduler_file: Optional[str] = None, retries: int = 1, timeout: float = 5.0,
                 env: Optional[dict] = None):
        import dask
        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler_file:
            _check_scheduler_file(scheduler_file)
        dask.config.set({"distributed.scheduler.allowed-failures": max(0, int(retries)),
                         "distributed.worker.daemon": False})
        try:
            if scheduler or scheduler_file:
                self.client = _client_within(lambda: Client(scheduler, scheduler_file=scheduler_file,
                                                            timeout=f"{timeout}s"), _scheduler_timeout())
            else:
                n = workers or cores()
                self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.ERROR,
                                            env={**WORKER_ENV, **(env or {})})
                self.client = Client(self.cluster)
        except (OSError, TimeoutError, ValueError, MemoryError) as exc:  # (ValueError: an address Dask cannot
            # read; MemoryError: a peer that answers junk, read as a frame length of exabytes)
            where = scheduler or f"the scheduler file {scheduler_file}"
            raise MtwinError(f"cannot reach the Dask scheduler at {where}: {exc}") from None
        self.retries = retries

    @property
    def threads(self) -> int:
        return max(1, sum(self.client.nthreads().values()))

    def describe(self) -> str:
        nt = self.client.nthreads()
        kind = "local cluster" if self.cluster is not None else f"scheduler {self.client.scheduler.address}"
        return f"{kind}: {len(nt)} worker(s), {sum(nt.values())} thread(s)"

    def run(self, jobs: list[Job], common: tuple, on_done: Callable[[Outcome], None], run: Callable) -> None:
        from distributed import as_completed

        # the biggest programs first (their size a proxy for their time): the batch does not end
        # on one long job that started last while the other workers idle
        todo = sorted(jobs, key=lambda j: _size(j))
        by_key = {}

        def submit():
            job = todo.pop()
            fut = self.client.submit(warmed_job, job, read_inputs(job), common, run, key=f"mtwin-job-{job.name}-{id(self)}",
                                     retries=self.retries, pure=False)
            by_key[fut.key] = job
            return fut

        flight = as_completed([submit() for _ in range(min(len(todo), IN_FLIGHT_PER_THREAD * self.threads))])
        try:
            for fut in flight:
                job = by_key.pop(fut.key)
                if fut.status == "finished":
                    out = fut.result()
                else:  # the task itself failed: a worker that died more often than allowed
                    try:
                        exc = fut.exception()
                    except Exception as lost:  # noqa: BLE001 (cancelled by the scheduler: lost with it)
                        exc = lost
                    out = Outcome(job.name, "failed", error=f"{type(exc).__name__}: {exc}")
                fut.release()
                on_done(out)
                if todo:
                    flight.add(submit())
        except BaseException:
            for fut in list(flight.futures):
                fut.cancel()
            raise

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()


def choose_runner(workers: Optional[int], scheduler: Optional[str], scheduler_file: Optional[str], retries: int,
                  n_jobs: int, on_message: Callable[[str], None] = lambda text: None) -> Optional["Cluster"]:
    """Where ``mtwin batch`` runs its jobs, from its options: a Dask cluster (local, of
    ``workers`` processes, one per core by default; or an existing one's ``scheduler`` or
    ``scheduler_file``), or None — one job at a time in this process (``workers`` 0, or Dask
    not installed: ``on_message`` says how to get it)."""

    if scheduler and scheduler_file:
        raise MtwinError("give --scheduler or --scheduler-file, not both")
    if scheduler_file:  # (Dask reads it to the end: a regular file of a manifest's size, like every input)
        from ..io import check_input

        check_input(scheduler_file, "manifest")
    if workers is not None and (scheduler or scheduler_file):
        raise MtwinError("--workers makes a local cluster; an existing cluster's workers are its own")
    if workers is not None and workers < 0:
        raise MtwinError(f"--workers {workers}: give 0 (in this process) or more")
    if not have_dask():
        if scheduler or scheduler_file or workers:
            raise MtwinError(f"running on Dask needs its packages: {FLEET_HINT}")
        on_message(f"note: Dask is not installed: the jobs run one at a time in this process (for one per core, or a "
            f"cluster: {FLEET_HINT})")
        return None
    if workers == 0 and not (scheduler or scheduler_file):
        return None
    return Cluster(workers=min(workers or cores(), n_jobs) if not (scheduler or scheduler_file) else None,
                   scheduler=scheduler, scheduler_file=scheduler_file, retries=retries)
