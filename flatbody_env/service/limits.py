"""The bounds of the analysis service: how much work one request or one job may ask for.

A request is answered in the request path only when its cost is bounded by :class:`Limits`;
larger work goes through ``POST /jobs`` (bounded too, by the ``job_*`` fields). A request over a
limit gets HTTP 413 with a message naming the limit and the value asked for.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields, replace

from flatbody_env.physics import validation


@dataclass(frozen=True, kw_only=True)
class Limits:
    """Bounds on request bodies and on the work of one request or job.

    Attributes
    ----------
    max_body_bytes : int
        Largest request body (bytes) but for ``POST /invariants``; larger bodies get 413.
    sync_samples, job_samples : int
        Most output times of ``POST /simulate`` / a ``simulate`` or ``record`` job.
    sync_t_end, job_t_end : float
        Longest horizon t_end (time units of the model) in the request path / in a job.
    sync_steps, job_steps : float
        Most fixed steps t_end / step of a fixed-step method.
    sync_grid : int
        Most grid points per axis of the root search of ``/ellipses`` and ``/stability``.
    job_map_grid : int
        Most grid points per axis of a ``stability-map`` job.
    job_family_seeds : int
        Most seeds of a ``family`` job.
    job_episodes : int
        Most episodes of an ``evaluate`` job.
    trajectory_samples : int
        Most samples of a trajectory sent to ``POST /invariants``.
    request_seconds : float
        Longest a request-path computation may run before it is answered with 413 (use a job);
        also the wall-clock budget of a request's integration.
    job_seconds : float
        Wall-clock budget of a job's integration.
    max_trajectory_body_bytes : int
        Largest body of ``POST /invariants`` (a trajectory); it is parsed in a worker process.
    max_times : int
        Most explicit output times (``times``) of a request or job: they are stored with the job.
    max_string : int
        Longest free-text string (a scene's ``description``; names and titles are shorter).
    max_queued_jobs : int
        Most jobs queued (not yet running) at once; more get 429 with ``Retry-After``.
    max_queued_per_client : int
        Most jobs queued at once by one client address; more get 429 with ``Retry-After``.
    max_stored_jobs : int
        Most jobs kept in the data dir (any status); more get 429 until some are deleted.
    max_list_jobs : int
        Most jobs in one ``GET /jobs`` page.
    max_list_bytes : int
        Largest ``GET /jobs`` answer: a page stops before it and says where the next one starts.
    retry_after_s : int
        The ``Retry-After`` of a 429.
    """

    max_body_bytes: int = 1024 * 1024
    sync_samples: int = 2001
    job_samples: int = 20001
    sync_t_end: float = 200.0
    job_t_end: float = 10_000.0
    sync_steps: float = 200_000.0
    job_steps: float = 20_000_000.0
    sync_grid: int = 401
    job_map_grid: int = 200
    job_family_seeds: int = 200
    job_episodes: int = 1000
    trajectory_samples: int = 20001
    request_seconds: float = 60.0
    job_seconds: float = 3600.0
    max_trajectory_body_bytes: int = 16 * 1024 * 1024
    max_times: int = 2001
    max_string: int = 2000
    max_queued_jobs: int = 64
    max_queued_per_client: int = 16
    max_stored_jobs: int = 1000
    max_list_jobs: int = 100
    max_list_bytes: int = 1024 * 1024
    retry_after_s: int = 10

    def as_dict(self) -> dict[str, float]:
        """The limits as JSON (``GET /limits``)."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    def with_environment(self, environ=None) -> Limits:
        """These limits with any ``FLATBODY_LIMIT_<NAME>`` environment variable applied
        (e.g. ``FLATBODY_LIMIT_MAX_QUEUED_JOBS=8``); a bad value is a ``ValueError`` naming the variable."""
        environ = os.environ if environ is None else environ
        changes = {}
        for f in fields(self):
            var = f"FLATBODY_LIMIT_{f.name.upper()}"
            if var not in environ:
                continue
            text = environ[var]
            try:
                value = int(text) if f.type in (int, "int") else float(text)
            except ValueError:
                raise ValueError(f"{var}: expected a number, got {text[:40]!r}") from None
            validation.requirement(
                var, text[:40], value > 0 and value == value and value != float("inf"), "be a finite number > 0"
            )
            changes[f.name] = value
        return replace(self, **changes) if changes else self


DEFAULT_LIMITS = Limits()
"""The limits ``flatbody serve`` runs with (each can be changed by ``FLATBODY_LIMIT_<NAME>``)."""


class LimitExceeded(ValueError):
    """A request or job over one of the :class:`Limits` (HTTP 413); the message names the limit."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"{field}: {message}")


def check_integration_cost(
    *, t_end: float, samples: int, step: float | None, in_job: bool, limits: Limits = DEFAULT_LIMITS
) -> None:
    """Refuse an integration whose horizon, output size or fixed-step count is over the limits.

    Raises
    ------
    LimitExceeded
        Naming the field and the limit (HTTP 413).
    """
    where = "job" if in_job else "request"
    hint = "" if in_job else "; send it as a job (POST /jobs with kind simulate or record)"
    t_max = limits.job_t_end if in_job else limits.sync_t_end
    n_max = limits.job_samples if in_job else limits.sync_samples
    steps_max = limits.job_steps if in_job else limits.sync_steps
    if t_end > t_max:
        raise LimitExceeded("t_end", f"at most {t_max:g} in a {where}, got {t_end:g}{hint}")
    if samples > n_max:
        raise LimitExceeded("samples", f"at most {n_max} output times in a {where}, got {samples}{hint}")
    if step is not None and t_end / step > steps_max:
        raise LimitExceeded(
            "step", f"t_end / step is at most {steps_max:g} fixed steps in a {where}, got {t_end / step:.3g}{hint}"
        )


__all__ = ["DEFAULT_LIMITS", "LimitExceeded", "Limits", "check_integration_cost"]
