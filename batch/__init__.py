"""helmet-anc batch: many sessions at once, on this machine or a Dask distributed cluster.

A helmet maker's lab measures many helmets, each on several heads and fits, both paths.
``run_batch`` identifies every session of a folder or CSV manifest (optionally
diagnosing and refining each), isolates bad sessions, resumes where an earlier run
stopped, and gives per helmet a nominal model with a multiplicative uncertainty bound::

    from batch import run_batch
    result = run_batch("sessions.csv", "out", workers=2)
    result.rows          # the results table (also out/results.csv, out/results.json)
    result.nominals      # {(helmet, path): NominalModel}, also out/nominal/*.json

``batch`` builds on ``sysid``; ``sysid`` never imports ``batch``.
"""

from .job import BatchResult, run_batch
from .manifest import SessionEntry, Skipped, find_sessions, read_sessions
from .nominal import NominalModel, nominal_model
from .riders import RiderSpread, rider_variant
from .runners import run_dask, run_local
from .simulated import write_simulated_campaign
from .task import SessionTask, input_hash, run_session

__all__ = ["BatchResult", "run_batch", "SessionEntry", "Skipped", "find_sessions", "read_sessions", "NominalModel", "nominal_model",
           "RiderSpread", "rider_variant", "run_dask", "run_local", "write_simulated_campaign", "SessionTask", "input_hash", "run_session"]
