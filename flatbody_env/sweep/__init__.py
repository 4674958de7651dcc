"""Sweeps on Dask: parameter maps, failure studies, families and many-seed training, resumable.

The app layer's sweep engine (it calls :mod:`analysis` and :mod:`agents`): :mod:`.tasks` (each
task a pure function of its key), :mod:`.store` (results by key in SQLite), :mod:`.cluster` (the
embedded or remote Dask cluster), :mod:`.runner` (run, store, resume), :mod:`.report` (the serial
commands' JSON form). The command is ``flatbody sweep``; its scaling benchmark (``flatbody bench sweep``)
is :mod:`flatbody_env.bench.sweep`.
"""

from flatbody_env.sweep.runner import SweepReport, run_sweep
from flatbody_env.sweep.store import ResultStore
from flatbody_env.sweep.tasks import KINDS, Task, plan

__all__ = ["KINDS", "ResultStore", "SweepReport", "Task", "plan", "run_sweep"]
