"""The JSON bodies of the analysis service: requests, answers and errors (pydantic models).

The request models check types, shapes and counts (HTTP 422 naming the field and the allowed
range); the physics of a body or a scene is checked by the package's one validator set
(:mod:`flatbody_env.physics.validation`, through ``Body.from_dict`` and ``load_scene``), whose
messages name the field too. The answers are the ``flatbody`` command's ``--json`` answers: the
service returns the very dicts the command prints; the answer models here document their shape
in the OpenAPI document.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, field_validator

from flatbody_env.service.limits import DEFAULT_LIMITS

Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
"""A finite number (NaN and ±inf are refused; so are strings and booleans)."""
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False, strict=True)]
"""A finite number > 0."""
Count = Annotated[int, Field(strict=True)]
"""An integer (not a float, string or boolean)."""
Flag = Annotated[bool, Field(strict=True)]
"""true or false (not 0/1 or a string)."""

DEFAULT_BODY = {"params": {"J": 1.0, "J3": 1.0}, "potential": {"name": "V3", "kappa": 1.0}, "thickness": {"a": 1.0, "b": 1.0}}
"""The default body of ``flatbody ellipses`` (J = J3 = 1, V3 with κ = 1, V_ϱ with a = b = 1)."""

FAMILY_PARAMETERS = ("s3", "p_theta", "k", "c", "d", "kappa", "a", "b", "J", "J3")
"""What a family may vary (``flatbody family --vary``)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


def _check_range(name: str, value: tuple[float, float]) -> tuple[float, float]:
    lo, hi = value
    if not 0 < lo < hi:
        raise ValueError(f"{name}: need 0 < LO < HI, got [{lo:g}, {hi:g}]")
    return value


# ----------------------------------------------------------------------------------------------
# requests
# ----------------------------------------------------------------------------------------------
class BodySpec(_Strict):
    """A body: a scene's ``params`` / ``potential`` / ``thickness`` objects (``Body.from_dict``).

    ``params`` is ``{"J", "J3"}`` (the analysis needs J1 = J2); ``potential`` is
    ``{"name": "V1", "k"}``, ``{"name": "V2", "c", "d"}`` or ``{"name": "V3", "kappa"}``
    (eqs. (37)-(39) of the paper); ``thickness`` is ``{"a", "b"}`` (eq. (40)) or null.
    """

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [DEFAULT_BODY]})

    params: dict[str, Finite] = Field(description='inertia: {"J", "J3"} (isotropic) or {"J1", "J2", "J3"}, each > 0')
    potential: dict[str, Union[Finite, str]] = Field(description='{"name": "V1"|"V2"|"V3", and its constants k | c, d | kappa (> 0)}')
    thickness: Union[dict[str, Finite], None] = Field(default=None, description='thickness potential V_rho {"a", "b"} (> 0), or null')
    spin_convention: Literal["corrected", "paper"] = "corrected"

    def as_data(self) -> dict[str, Any]:
        """The dict ``Body.from_dict`` reads."""
        return self.model_dump(mode="python")


class SpinsRequest(_Strict):
    """A body and the spins (s3, p_θ) of ``flatbody ellipses`` / ``flatbody stability``."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"body": DEFAULT_BODY, "s3": 2.0, "p_theta": 0.5}]})

    body: BodySpec
    s3: Finite = Field(description="spin component s3 (conserved with |s|)")
    p_theta: Finite = Field(description="material momentum p_theta")
    branch: Literal["N", "A", "all"] = Field("N", description="N: s1 = s2 = 0 (paper); A: in-plane axis (needs spin)")
    spin: Union[Finite, None] = Field(None, description="spin about the in-plane axis for branch A")
    lam_range: tuple[Positive, Positive] = Field((0.02, 50.0), description="search range of lambda [LO, HI], 0 < LO < HI")
    mu_range: tuple[Positive, Positive] = Field((0.02, 50.0), description="search range of mu [LO, HI], 0 < LO < HI")
    grid: Count = Field(121, ge=8, le=DEFAULT_LIMITS.sync_grid, description="grid points per axis of the root search")

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class SimulateRequest(_Strict):
    """``flatbody simulate``: a scene (object or built-in name) and the integration settings."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"scene": "default", "t_end": 2.0, "samples": 21}]})

    scene: Union[str, dict[str, Any]] = Field("default", description="a scene object (as a scene JSON file) or a built-in scene name")
    t_end: Union[Positive, None] = Field(None, description="final time (default: the scene's t_end)")
    times: Union[list[Finite], None] = Field(None, min_length=1, max_length=DEFAULT_LIMITS.job_samples,
                                             description="output times in [0, t_end], increasing (default: an even grid)")
    samples: Union[Count, None] = Field(None, ge=2, le=DEFAULT_LIMITS.job_samples, description="number of evenly spaced output times (default 101)")
    method: str = Field("auto", max_length=64, description="integrator (GET /methods) or auto: the fastest that meets rtol/atol")
    rtol: Positive = Field(1e-10, description="relative tolerance (adaptive methods)")
    atol: Positive = Field(1e-10, description="absolute tolerance (adaptive methods)")
    step: Union[Positive, None] = Field(None, description="step size (fixed-step methods)")
    model: Literal["auto", "two-polar", "regular"] = "auto"
    with_rotation: Flag = Field(False, description="also integrate R and output 'rotation'")


class TrajectoryRequest(_Strict):
    """A trajectory as ``flatbody simulate`` writes it (``Trajectory.to_dict()``), plus an optional body.

    Without ``body`` the body of the built-in scene named in ``meta.scene`` is used (as the CLI does).
    """

    t: list[Finite] = Field(min_length=1, max_length=DEFAULT_LIMITS.trajectory_samples)
    state: dict[str, list[Finite]]
    energy: Union[list[Finite], None] = None
    casimir: Union[list[Finite], None] = None
    p_theta: Union[list[Finite], None] = None
    rotation: Union[list[list[list[Finite]]], None] = None
    initial_state: Union[dict[str, Finite], None] = None
    meta: Union[dict[str, Any], None] = None
    body: Union[BodySpec, None] = Field(None, description="the body (default: the built-in scene named in meta.scene)")

    def trajectory(self) -> dict[str, Any]:
        """The trajectory dict ``invariants_along`` reads."""
        out: dict[str, Any] = {"t": self.t, "state": self.state}
        for key in ("energy", "casimir", "p_theta", "rotation", "initial_state", "meta"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        return out


class _IntegrationParams(_Strict):
    scene: Union[str, dict[str, Any]] = Field("default", description="a scene object or a built-in scene name")
    t_end: Union[Positive, None] = Field(None, description="final time (default: the scene's t_end)")
    method: str = Field("auto", max_length=64)
    rtol: Positive = 1e-10
    atol: Positive = 1e-10
    step: Union[Positive, None] = None
    model: Literal["auto", "two-polar", "regular"] = "auto"


class SimulateJobParams(SimulateRequest):
    """A ``simulate`` job: as ``POST /simulate``, with the larger job limits; artifact ``trajectory.json``."""


class RecordJobParams(_IntegrationParams):
    """A ``record`` job (``flatbody record``): simulate with R(t) and write a rerun recording ``recording.rrd``."""

    samples: Count = Field(401, ge=2, le=DEFAULT_LIMITS.job_samples, description="recorded time steps")
    title: Union[str, None] = Field(None, max_length=200, description="recording title")
    tensor_every: Count = Field(1, ge=1, le=10_000, description="log the tensors every N-th step")


class FamilyJobParams(_Strict):
    """A ``family`` job (``flatbody family``): artifacts ``family.png`` and ``family.csv``."""

    body: BodySpec = Field(default_factory=lambda: BodySpec(**DEFAULT_BODY))
    vary: Literal[FAMILY_PARAMETERS] = "s3"  # type: ignore[valid-type]
    start: Finite = Field(0.05, alias="from", description="start of the range")
    stop: Finite = Field(4.0, alias="to", description="end of the range")
    s3: Union[Finite, None] = Field(None, description="s3 held fixed (default 2)")
    p_theta: Union[Finite, None] = Field(None, description="p_theta held fixed (default 0.5)")
    seeds: Count = Field(5, ge=2, le=DEFAULT_LIMITS.job_family_seeds, description="parameter values at which all solutions are sought")
    step: Union[Positive, None] = Field(None, description="largest continuation step (default range/60)")
    lam_range: tuple[Positive, Positive] = (0.02, 50.0)
    mu_range: tuple[Positive, Positive] = (0.02, 50.0)
    grid: Count = Field(121, ge=8, le=DEFAULT_LIMITS.sync_grid)

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class StabilityMapJobParams(_Strict):
    """A ``stability-map`` job (``flatbody stability-map``): artifacts ``stability-map.png`` and ``.csv``."""

    body: BodySpec = Field(default_factory=lambda: BodySpec(**DEFAULT_BODY))
    lam_range: tuple[Positive, Positive] = (1.02, 3.0)
    mu_range: tuple[Positive, Positive] = (0.3, 3.0)
    grid: Count = Field(30, ge=4, le=DEFAULT_LIMITS.job_map_grid, description="grid points per axis")

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class EvaluateJobParams(_Strict):
    """An ``evaluate`` job (``flatbody evaluate``) of the shipped agent; artifact ``evaluation.json``.

    Only the agent shipped with the package is evaluated: models are never loaded from request data.
    """

    episodes: Count = Field(20, ge=1, le=DEFAULT_LIMITS.job_episodes)
    seed: Count = Field(10_000, ge=0, le=2**31 - 1)
    baselines: Flag = Field(True, description="also evaluate the zero, random and heuristic baselines")


class SimulateJob(_Strict):
    kind: Literal["simulate"]
    params: SimulateJobParams = Field(default_factory=SimulateJobParams)


class RecordJob(_Strict):
    kind: Literal["record"]
    params: RecordJobParams = Field(default_factory=RecordJobParams)


class FamilyJob(_Strict):
    kind: Literal["family"]
    params: FamilyJobParams = Field(default_factory=FamilyJobParams)


class StabilityMapJob(_Strict):
    kind: Literal["stability-map"]
    params: StabilityMapJobParams = Field(default_factory=StabilityMapJobParams)


class EvaluateJob(_Strict):
    kind: Literal["evaluate"]
    params: EvaluateJobParams = Field(default_factory=EvaluateJobParams)


JobRequest = Annotated[Union[SimulateJob, RecordJob, FamilyJob, StabilityMapJob, EvaluateJob], Field(discriminator="kind")]
"""``POST /jobs``: ``{"kind", "params"}``."""

JOB_KINDS = ("simulate", "family", "stability-map", "record", "evaluate")


# ----------------------------------------------------------------------------------------------
# answers
# ----------------------------------------------------------------------------------------------
class Health(BaseModel):
    status: Literal["ok"]
    version: str


class Ellipse(BaseModel):
    """One stationary ellipse (``StationaryEllipse.to_dict()``)."""

    state: dict[str, float]
    omega3: float
    theta_dot: float
    energy: float
    residual: float


class EllipsesAnswer(BaseModel):
    solutions: list[Ellipse]


class Stability(BaseModel):
    """The stability of one stationary ellipse (``StabilityResult.to_dict()``)."""

    state: dict[str, float]
    eigenvalues: list[list[float]] = Field(description="[[re, im], ...]")
    max_real_part: float
    classification: str


class StabilityAnswer(BaseModel):
    solutions: list[Stability]


class TrajectoryAnswer(BaseModel):
    """``Trajectory.to_dict()``: the ``flatbody simulate`` JSON."""

    t: list[float]
    state: dict[str, list[float]]
    energy: list[float]
    casimir: list[float]
    p_theta: list[float]
    rotation: Union[list[list[list[float]]], None] = None
    initial_state: Union[dict[str, float], None] = None
    meta: dict[str, Any]


class DriftRow(BaseModel):
    name: str
    initial: float
    max_abs_drift: float
    max_rel_drift: float
    conserved: bool


class InvariantsAnswer(BaseModel):
    """``InvariantReport.to_dict()``: the ``flatbody invariants --json`` answer."""

    model_config = ConfigDict(extra="allow")

    samples: int
    t_end: float
    drift: list[DriftRow]


class MethodAnswer(BaseModel):
    """``MethodInfo.as_dict()``."""

    name: str
    adaptive: bool
    order: int
    chart: str
    compiled: bool
    preserves: list[str]
    description: str


class JobCreated(BaseModel):
    id: str


class JobStatus(BaseModel):
    """A job's state; ``result`` when done (the CLI's JSON answer), ``error`` when failed."""

    id: str
    kind: str
    status: Literal["queued", "running", "done", "failed"]
    progress: float = Field(ge=0.0, le=1.0, description="fraction done, reported by the worker while the job runs; never decreases")
    params: dict[str, Any]
    result: Union[Any, None] = None
    error: Union[str, None] = None
    artifacts: list[str] = Field(description="file names for GET /jobs/{id}/artifact?name=...")
    created: float = Field(description="Unix time")
    started: Union[float, None] = None
    finished: Union[float, None] = None
    stage: Union[str, None] = Field(None, description="what the job is doing now (e.g. 'row 12 of 30'), while it runs")
    elapsed: Union[float, None] = Field(None, description="seconds since the job started (to its end once it has ended)")
    remaining: Union[float, None] = Field(None, description="while it runs: estimated seconds left at its mean rate so far")


class JobList(BaseModel):
    jobs: list[JobStatus]


class JobDeleted(BaseModel):
    id: str
    cancelled: bool = Field(description="the job was queued or running and was stopped")
    deleted: bool


class ErrorAnswer(BaseModel):
    """Every error: one line (``detail``) naming the field and the allowed range or the limit."""

    detail: str
    kind: Literal["validation", "too-large", "integration", "not-found", "conflict", "unavailable"]
    field: Union[str, None] = Field(None, description="the request field at fault (dotted)")
    when: Union[float, None] = Field(None, description="integration failures: the time t at which it failed")
    why: Union[str, None] = Field(None, description="integration failures: the reason (IntegrationError)")
    method: Union[str, None] = None
