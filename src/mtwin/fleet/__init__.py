"""Fleet runs: many programs × many machines' twin files, each job the command a user would
type, run one by one in this process or on Dask (a local cluster, or an existing one).

``manifest`` (what to run), ``job`` (one job, a pure function of its inputs' bytes),
``runner`` (where: in process, or on Dask), ``batch`` (outputs written as results arrive,
and the summary).  ``mtwin batch`` is the command line over it (docs/fleet.md).
"""
from __future__ import annotations

from .batch import Batch, check_out_dir, run_batch
from .job import Outcome, run_job
from .manifest import COMMANDS, NEEDS_MEASUREMENT, Job, ManifestError, jobs_from_paths, own_options, read_manifest, read_recipe
from .runner import choose_runner

__all__ = ["Batch", "COMMANDS", "Job", "ManifestError", "NEEDS_MEASUREMENT", "Outcome", "check_out_dir",
           "choose_runner", "jobs_from_paths", "own_options", "read_batch_jobs", "read_manifest", "read_recipe",
           "run_batch", "run_job"]


def read_batch_jobs(command: str, manifest=None, programs=(), twins=(), measurements=()) -> list:
    """The jobs from a manifest, or from programs × twin files."""
    if manifest and (programs or twins or measurements):
        raise ManifestError("give either --manifest or programs (with --twin, --measurement), not both: a manifest "
                            "names each job's twin file and measurement")
    if manifest:
        return read_manifest(manifest, command)
    return jobs_from_paths(command, list(programs), list(twins), list(measurements))
