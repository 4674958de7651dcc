"""The JSON bodies of the analysis service: requests, answers and errors (pydantic models).

The request models state every bound the service checks (HTTP 422 naming the field and the allowed
range, as the OpenAPI document says): the ranges of the package's one validator set
(:mod:`flatbody_env.physics.validation`: constants, stretches, spins and momenta, t_end,
tolerances, grids, seeds), the service's limits (:mod:`flatbody_env.service.limits`: output times, grids,
stored strings and arrays) and the shapes of bodies and scenes. Every bound, default and range in
a description is read from those modules and from the library's named defaults
(:func:`~flatbody_env.physics.body.default_body`, :class:`~flatbody_env.integrators.base.Tolerances`,
:data:`~flatbody_env.simulation.DEFAULT_SAMPLES`, :class:`analysis.stationary.SearchBox`,
:data:`analysis.families.PARAMETERS` and the family and map defaults beside it,
:data:`agents.evaluate.EVAL_SEED`), never written again here. What a schema cannot say (a
trajectory's arrays as long as its ``t``, output times increasing, λ ≠ μ, J1 = J2 for the
analysis, from < to, a step only for a fixed-step method) is checked by the same validators when the request is
computed, and a job's when it is posted, before it is queued (422 too: :func:`flatbody_env.service.answers.check_job`).
The answers are the ``flatbody`` command's ``--json`` answers; the answer models document their
shape in the OpenAPI document.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    field_validator,
    model_serializer,
)

from agents.evaluate import EVAL_SEED
from analysis.families import (
    DEFAULT_FAMILY_RANGE,
    DEFAULT_P_THETA,
    DEFAULT_S3,
    DEFAULT_SEEDS,
    MAP_GRID,
    MAP_LAM_RANGE,
    MAP_MU_RANGE,
    PARAMETERS,
)
from analysis.stationary import SearchBox
from flatbody_env.integrators.base import Tolerances
from flatbody_env.physics.body import default_body
from flatbody_env.physics.validation import (
    FAMILY_SEEDS_RANGE,
    MAX_SAMPLES,
    MAX_SEED,
    MIN_SAMPLES,
    MOMENTUM_MAX,
    PARAM_RANGE,
    SEARCH_GRID_RANGE,
    STRETCH_RANGE,
    SWEEP_GRID_RANGE,
    TOL_RANGE,
    shown,
)
from flatbody_env.service.limits import DEFAULT_LIMITS
from flatbody_env.simulation import DEFAULT_SAMPLES

L = DEFAULT_LIMITS
BOX = SearchBox()
"""The library's search box (its λ, μ ranges and grid are the defaults of the ellipse and family requests)."""
TOLERANCES = Tolerances()
"""The library's default tolerances (rtol, atol of every integration request)."""

_PARAM_TEXT = f"[{PARAM_RANGE[0]:g}, {PARAM_RANGE[1]:g}]"
_MOMENTUM_TEXT = f"±{MOMENTUM_MAX:g}"
_TOL_TEXT = f"[{TOL_RANGE[0]:g}, {TOL_RANGE[1]:g}]"
_SEARCH_TEXT = f"{STRETCH_RANGE[0]:g} <= LO < HI <= {STRETCH_RANGE[1]:g}"

Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
"""A finite number (NaN and ±inf are refused; so are strings and booleans)."""
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False, strict=True)]
"""A finite number > 0."""
Constant = Annotated[float, Field(ge=PARAM_RANGE[0], le=PARAM_RANGE[1], allow_inf_nan=False, strict=True)]
"""A body constant (J, J3, k, c, d, κ, a, b) in :data:`~flatbody_env.physics.validation.PARAM_RANGE`."""
Stretch = Annotated[float, Field(ge=STRETCH_RANGE[0], le=STRETCH_RANGE[1], allow_inf_nan=False, strict=True)]
"""λ, μ or ϱ in :data:`~flatbody_env.physics.validation.STRETCH_RANGE` (states and search ranges)."""
Momentum = Annotated[float, Field(ge=-MOMENTUM_MAX, le=MOMENTUM_MAX, allow_inf_nan=False, strict=True)]
"""A spin or momentum component (s1, s2, s3, p_θ, …) within ± :data:`~flatbody_env.physics.validation.MOMENTUM_MAX`."""
Tolerance = Annotated[float, Field(ge=TOL_RANGE[0], le=TOL_RANGE[1], allow_inf_nan=False, strict=True)]
"""rtol or atol in :data:`~flatbody_env.physics.validation.TOL_RANGE`."""


def _integral(value: Any) -> Any:
    """An integral JSON number written with a fraction or exponent (``263.0``, ``2e2``) as the integer it is:
    JSON Schema counts it an integer, so the service does too. ``263.5``, strings and booleans are left
    as they are (and refused by the strict integer that follows)."""
    return int(value) if isinstance(value, float) and value.is_integer() and abs(value) < 2**53 else value


def Count(lo: int, hi: int):  # noqa: N802 - a type, spelled as one
    """An integer in [lo, hi]: an integral JSON number (``263`` or ``263.0``), not a fraction (``263.5``), a string
    or a boolean. The bounds sit inside the strict integer, after the conversion, so the OpenAPI document states
    them as ``minimum`` / ``maximum``."""
    return Annotated[int, Field(strict=True, ge=lo, le=hi), BeforeValidator(_integral)]


Flag = Annotated[bool, Field(strict=True)]
"""true or false (not 0/1 or a string)."""
Name = Annotated[str, Field(max_length=64)]
"""A short name (a scene's, a method's)."""

DEFAULT_BODY = default_body().to_dict()
"""The default body of ``flatbody ellipses`` (:func:`~flatbody_env.physics.body.default_body`)."""

FAMILY_PARAMETERS = PARAMETERS
"""What a family may vary (``flatbody family --vary``, :data:`analysis.families.PARAMETERS`)."""

RECORD_JOB_SAMPLES = 401
"""Recorded time steps of a ``record`` job when the request gives none (fewer than ``flatbody record``'s 1001: a job's
recording is downloaded)."""


def _builtin_scene_names() -> tuple[str, ...]:
    names = []
    for entry in sorted(resources.files("flatbody_env.scenes").iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".json"):
            names.append(json.loads(entry.read_text(encoding="utf-8")).get("name", entry.name[:-5]))
    return tuple(names)


BUILTIN_SCENES = _builtin_scene_names()
"""The names of the built-in scenes (``GET /scenes``)."""
SceneName = Literal[BUILTIN_SCENES]  # type: ignore[valid-type]

UNION_TAGS = frozenset({"isotropic", "three-moments", "V1", "V2", "V3", "scene-name", "scene-object"})
"""Names pydantic puts in an error's location for a member of a union; left out of the field's dotted name."""


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
class IsotropicInertia(_Strict):
    """``{"J", "J3"}``: J1 = J2 = J (eq. (29))."""

    J: Constant
    J3: Constant


class Inertia(_Strict):
    """``{"J1", "J2", "J3"}`` (the analysis needs J1 = J2)."""

    J1: Constant
    J2: Constant
    J3: Constant


def _inertia_tag(value: Any) -> str:
    """The union member of ``params``: a JSON object (validation) or a model instance (serialization; pydantic calls
    the discriminator on what it serializes too, so an :class:`Inertia` must be named as such)."""
    if isinstance(value, (Inertia, IsotropicInertia)):
        return "three-moments" if isinstance(value, Inertia) else "isotropic"
    return "three-moments" if isinstance(value, dict) and ("J1" in value or "J2" in value) else "isotropic"


InertiaSpec = Annotated[
    Annotated[IsotropicInertia, Tag("isotropic")] | Annotated[Inertia, Tag("three-moments")],
    Discriminator(_inertia_tag),
]


class PotentialV1(_Strict):
    """V1 (eq. (37)) with its constant k."""

    name: Literal["V1"]
    k: Constant


class PotentialV2(_Strict):
    """V2 (eq. (38)) with its constants c, d."""

    name: Literal["V2"]
    c: Constant
    d: Constant


class PotentialV3(_Strict):
    """V3 (eq. (39)) with its constant κ (``kappa``)."""

    name: Literal["V3"]
    kappa: Constant


PotentialSpec = Annotated[PotentialV1 | PotentialV2 | PotentialV3, Field(discriminator="name")]


class ThicknessSpec(_Strict):
    """The thickness potential V_ϱ (eq. (40)) with its constants a, b."""

    a: Constant
    b: Constant


class BodySpec(_Strict):
    """A body: a scene's ``params`` / ``potential`` / ``thickness`` objects (``Body.from_dict``).

    ``params`` is ``{"J", "J3"}`` (the analysis needs J1 = J2) or ``{"J1", "J2", "J3"}``; ``potential``
    is ``{"name": "V1", "k"}``, ``{"name": "V2", "c", "d"}`` or ``{"name": "V3", "kappa"}``
    (eqs. (37)-(39) of the paper); ``thickness`` is ``{"a", "b"}`` (eq. (40)) or null. Every constant
    lies in :data:`~flatbody_env.physics.validation.PARAM_RANGE`.
    """

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [DEFAULT_BODY]})

    params: InertiaSpec = Field(
        description=f'inertia: {{"J", "J3"}} (isotropic) or {{"J1", "J2", "J3"}}, each in {_PARAM_TEXT}'
    )
    potential: PotentialSpec = Field(
        description=f'{{"name": "V1"|"V2"|"V3", and its constants k | c, d | kappa, in {_PARAM_TEXT}}}'
    )
    thickness: ThicknessSpec | None = Field(default=None, description='thickness potential V_rho {"a", "b"}, or null')
    spin_convention: Literal["corrected", "paper"] = "corrected"

    def as_data(self) -> dict[str, Any]:
        """The dict ``Body.from_dict`` reads."""
        return self.model_dump(mode="python", by_alias=True)


class AnalysisBodySpec(BodySpec):
    """A body for the analysis (ellipses, stability, families, maps): the corrected bracket only (erratum E3)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [DEFAULT_BODY]})

    spin_convention: Literal["corrected"] = "corrected"


class StateSpec(_Strict):
    """A state (a scene's ``state``): λ, μ, ϱ in :data:`~flatbody_env.physics.validation.STRETCH_RANGE`, every other
    entry within ± :data:`~flatbody_env.physics.validation.MOMENTUM_MAX` (λ ≠ μ)."""

    s1: Momentum
    s2: Momentum
    s3: Momentum
    p_theta: Momentum
    p_lambda: Momentum
    p_mu: Momentum
    p_rho: Momentum
    lambda_: Stretch = Field(alias="lambda")
    mu: Stretch
    rho: Stretch
    theta: Momentum


class SceneSpec(BodySpec):
    """A scene object, as a scene JSON file (``scene_from_dict``); ``t_end`` at most the request limit."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    name: Name | None = None
    description: Annotated[str, Field(max_length=L.max_string)] | None = None
    thickness: ThicknessSpec | None = Field(description='thickness potential V_rho {"a", "b"}, or null (required)')
    state: StateSpec
    t_end: Annotated[float, Field(gt=0, le=L.sync_t_end, allow_inf_nan=False, strict=True)] | None = None

    @model_serializer(mode="wrap")
    def _without_nulls(self, handler):
        data = handler(self)
        return {k: v for k, v in data.items() if v is not None or k == "thickness"}


class JobSceneSpec(SceneSpec):
    """A scene object of a job: ``t_end`` at most the job limit."""

    t_end: Annotated[float, Field(gt=0, le=L.job_t_end, allow_inf_nan=False, strict=True)] | None = None


def _scene_tag(value: Any) -> str:
    return "scene-name" if isinstance(value, str) else "scene-object"


RequestScene = Annotated[
    Annotated[SceneName, Tag("scene-name")] | Annotated[SceneSpec, Tag("scene-object")], Discriminator(_scene_tag)
]
JobScene = Annotated[
    Annotated[SceneName, Tag("scene-name")] | Annotated[JobSceneSpec, Tag("scene-object")],
    Discriminator(_scene_tag),
]


SearchRange = tuple[Stretch, Stretch]
SearchGrid = Count(SEARCH_GRID_RANGE[0], min(L.sync_grid, SEARCH_GRID_RANGE[1]))
"""Grid points per axis of a root search: :data:`~flatbody_env.physics.validation.SEARCH_GRID_RANGE` within the request limit."""
STEP_MIN_REQUEST = L.sync_t_end / L.sync_steps
"""Smallest fixed step of a request: ``t_end / step`` stays within the request's step limit for any t_end."""
STEP_MIN_JOB = L.job_t_end / L.job_steps
"""Smallest fixed step of a job."""


class SpinsRequest(_Strict):
    """A body and the spins (s3, p_θ) of ``flatbody ellipses`` / ``flatbody stability``."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"body": DEFAULT_BODY, "s3": DEFAULT_S3, "p_theta": DEFAULT_P_THETA}]},
    )

    body: AnalysisBodySpec
    s3: Momentum = Field(description=f"spin component s3 (conserved with |s|), within {_MOMENTUM_TEXT}")
    p_theta: Momentum = Field(description=f"material momentum p_theta, within {_MOMENTUM_TEXT}")
    branch: Literal["N", "A", "all"] = Field("N", description="N: s1 = s2 = 0 (paper); A: in-plane axis (needs spin)")
    spin: Momentum | None = Field(
        None, description=f"spin about the in-plane axis for branch A, within {_MOMENTUM_TEXT}"
    )
    lam_range: SearchRange = Field(BOX.lam, description=f"search range of lambda [LO, HI], {_SEARCH_TEXT}")
    mu_range: SearchRange = Field(BOX.mu, description=f"search range of mu [LO, HI], {_SEARCH_TEXT}")
    grid: SearchGrid = Field(BOX.n, description="grid points per axis of the root search")

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class SimulateRequest(_Strict):
    """``flatbody simulate``: a scene (object or built-in name) and the integration settings, within the request limits."""

    model_config = ConfigDict(
        extra="forbid", json_schema_extra={"examples": [{"scene": "default", "t_end": 2.0, "samples": 21}]}
    )

    scene: RequestScene = Field("default", description="a scene object (as a scene JSON file) or a built-in scene name")
    t_end: Annotated[float, Field(gt=0, le=L.sync_t_end, allow_inf_nan=False, strict=True)] | None = Field(
        None, description="final time (default: the scene's t_end)"
    )
    times: list[Annotated[float, Field(ge=0, le=L.sync_t_end, allow_inf_nan=False, strict=True)]] | None = Field(
        None,
        min_length=1,
        max_length=L.max_times,
        description="output times in [0, t_end], increasing (default: an even grid)",
    )
    samples: Count(MIN_SAMPLES, L.sync_samples) | None = Field(
        None, description=f"number of evenly spaced output times (default {DEFAULT_SAMPLES})"
    )
    method: Name = Field("auto", description="integrator (GET /methods) or auto: the fastest that meets rtol/atol")
    rtol: Tolerance = Field(TOLERANCES.rtol, description=f"relative tolerance (adaptive methods), in {_TOL_TEXT}")
    atol: Tolerance = Field(TOLERANCES.atol, description=f"absolute tolerance (adaptive methods), in {_TOL_TEXT}")
    step: Annotated[float, Field(ge=STEP_MIN_REQUEST, le=L.sync_t_end, allow_inf_nan=False, strict=True)] | None = (
        Field(None, description="step size (fixed-step methods)")
    )
    model: Literal["auto", "two-polar", "regular"] = "auto"
    with_rotation: Flag = Field(False, description="also integrate R and output 'rotation'")


class TrajectoryRequest(_Strict):
    """A trajectory as ``flatbody simulate`` writes it (``Trajectory.to_dict()``), plus an optional body.

    Without ``body`` the body of the built-in scene named in ``meta.scene`` is used (as the CLI does).
    The body of ``POST /invariants`` may be larger than other bodies; it is read in a worker process.
    """

    t: list[Finite] = Field(min_length=1, max_length=L.trajectory_samples)
    state: dict[str, Annotated[list[Finite], Field(max_length=L.trajectory_samples)]] = Field(max_length=16)
    energy: Annotated[list[Finite], Field(max_length=L.trajectory_samples)] | None = None
    casimir: Annotated[list[Finite], Field(max_length=L.trajectory_samples)] | None = None
    p_theta: Annotated[list[Finite], Field(max_length=L.trajectory_samples)] | None = None
    rotation: (
        Annotated[
            list[Annotated[list[Annotated[list[Finite], Field(max_length=3)]], Field(max_length=3)]],
            Field(max_length=L.trajectory_samples),
        ]
        | None
    ) = None
    initial_state: Annotated[dict[str, Finite], Field(max_length=16)] | None = None
    meta: Annotated[dict[str, Any], Field(max_length=64)] | None = None
    body: BodySpec | None = Field(None, description="the body (default: the built-in scene named in meta.scene)")

    def trajectory(self) -> dict[str, Any]:
        """The trajectory dict ``invariants_along`` reads."""
        out: dict[str, Any] = {"t": self.t, "state": self.state}
        for key in ("energy", "casimir", "p_theta", "rotation", "initial_state", "meta"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        return out


class SimulateJobParams(_Strict):
    """A ``simulate`` job: as ``POST /simulate``, with the larger job limits; artifact ``trajectory.json``."""

    model_config = ConfigDict(
        extra="forbid", json_schema_extra={"examples": [{"scene": "default", "t_end": 200.0, "samples": 2001}]}
    )

    scene: JobScene = Field("default", description="a scene object (as a scene JSON file) or a built-in scene name")
    t_end: Annotated[float, Field(gt=0, le=L.job_t_end, allow_inf_nan=False, strict=True)] | None = Field(
        None, description="final time (default: the scene's t_end)"
    )
    times: list[Annotated[float, Field(ge=0, le=L.job_t_end, allow_inf_nan=False, strict=True)]] | None = Field(
        None,
        min_length=1,
        max_length=L.max_times,
        description="output times in [0, t_end], increasing (default: an even grid)",
    )
    samples: Count(MIN_SAMPLES, L.job_samples) | None = Field(
        None, description=f"number of evenly spaced output times (default {DEFAULT_SAMPLES})"
    )
    method: Name = Field("auto", description="integrator (GET /methods) or auto")
    rtol: Tolerance = TOLERANCES.rtol
    atol: Tolerance = TOLERANCES.atol
    step: Annotated[float, Field(ge=STEP_MIN_JOB, le=L.job_t_end, allow_inf_nan=False, strict=True)] | None = None
    model: Literal["auto", "two-polar", "regular"] = "auto"
    with_rotation: Flag = Field(False, description="also integrate R and output 'rotation'")


class RecordJobParams(_Strict):
    """A ``record`` job (``flatbody record``): simulate with R(t) and write a rerun recording ``recording.rrd``."""

    scene: JobScene = Field("default", description="a scene object or a built-in scene name")
    t_end: Annotated[float, Field(gt=0, le=L.job_t_end, allow_inf_nan=False, strict=True)] | None = Field(
        None, description="final time (default: the scene's t_end)"
    )
    method: Name = "auto"
    rtol: Tolerance = TOLERANCES.rtol
    atol: Tolerance = TOLERANCES.atol
    step: Annotated[float, Field(ge=STEP_MIN_JOB, le=L.job_t_end, allow_inf_nan=False, strict=True)] | None = None
    model: Literal["auto", "two-polar", "regular"] = "auto"
    samples: Count(MIN_SAMPLES, L.job_samples) = Field(RECORD_JOB_SAMPLES, description="recorded time steps")
    title: Annotated[str, Field(max_length=200)] | None = Field(None, description="recording title")
    tensor_every: Count(1, MAX_SAMPLES) = Field(1, description="log the tensors every N-th step")


class FamilyJobParams(_Strict):
    """A ``family`` job (``flatbody family``): artifacts ``family.png`` and ``family.csv``."""

    body: AnalysisBodySpec = Field(default_factory=lambda: AnalysisBodySpec(**DEFAULT_BODY))
    vary: Literal[FAMILY_PARAMETERS] = "s3"  # type: ignore[valid-type]
    start: Momentum = Field(
        DEFAULT_FAMILY_RANGE[0], alias="from", description=f"start of the range (within {_MOMENTUM_TEXT})"
    )
    stop: Momentum = Field(
        DEFAULT_FAMILY_RANGE[1],
        alias="to",
        description=f"end of the range (within {_MOMENTUM_TEXT}; greater than from)",
    )
    s3: Momentum | None = Field(None, description=f"s3 held fixed (default {DEFAULT_S3:g})")
    p_theta: Momentum | None = Field(None, description=f"p_theta held fixed (default {DEFAULT_P_THETA:g})")
    seeds: Count(FAMILY_SEEDS_RANGE[0], min(L.job_family_seeds, FAMILY_SEEDS_RANGE[1])) = Field(
        DEFAULT_SEEDS, description="parameter values at which all solutions are sought"
    )
    step: Annotated[float, Field(gt=0, le=2 * MOMENTUM_MAX, allow_inf_nan=False, strict=True)] | None = Field(
        None, description="largest continuation step (default range/60)"
    )
    lam_range: SearchRange = BOX.lam
    mu_range: SearchRange = BOX.mu
    grid: SearchGrid = BOX.n

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class StabilityMapJobParams(_Strict):
    """A ``stability-map`` job (``flatbody stability-map``): artifacts ``stability-map.png`` and ``.csv``."""

    body: AnalysisBodySpec = Field(default_factory=lambda: AnalysisBodySpec(**DEFAULT_BODY))
    lam_range: SearchRange = MAP_LAM_RANGE
    mu_range: SearchRange = MAP_MU_RANGE
    grid: Count(SWEEP_GRID_RANGE[0], L.job_map_grid) = Field(MAP_GRID, description="grid points per axis")

    @field_validator("lam_range", "mu_range")
    @classmethod
    def _ranges(cls, value, info):
        return _check_range(info.field_name, value)


class EvaluateJobParams(_Strict):
    """An ``evaluate`` job (``flatbody evaluate``) of the shipped agent; artifact ``evaluation.json``.

    Only the agent shipped with the package is evaluated: models are never loaded from request data.
    """

    episodes: Count(1, L.job_episodes) = 20
    seed: Count(0, MAX_SEED) = EVAL_SEED
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


JobRequest = Annotated[SimulateJob | RecordJob | FamilyJob | StabilityMapJob | EvaluateJob, Field(discriminator="kind")]
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
    rotation: list[list[list[float]]] | None = None
    initial_state: dict[str, float] | None = None
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
    progress: float = Field(
        ge=0.0, le=1.0, description="fraction done, reported by the worker while the job runs; never decreases"
    )
    params: dict[str, Any]
    result: Any | None = Field(None, description="the answer, when done (left out of GET /jobs)")
    error: str | None = None
    artifacts: list[str] = Field(description="file names for GET /jobs/{id}/artifact?name=...")
    created: float = Field(description="Unix time")
    started: float | None = None
    finished: float | None = None
    stage: str | None = Field(None, description="what the job is doing now (e.g. 'row 12 of 30'), while it runs")
    elapsed: float | None = Field(None, description="seconds since the job started (to its end once it has ended)")
    remaining: float | None = Field(None, description="while it runs: estimated seconds left at its mean rate so far")


class JobList(BaseModel):
    """A page of jobs, newest first; ``next`` is the ``before`` of the next page (null: no more)."""

    jobs: list[JobStatus]
    next: str | None = Field(None, description="pass as ?before= for the next page; null when this page is the last")


class JobDeleted(BaseModel):
    id: str
    cancelled: bool = Field(description="the job was queued or running and was stopped")
    deleted: bool


class ErrorAnswer(BaseModel):
    """Every error: one line (``detail``) naming the field and the allowed range or the limit."""

    detail: str
    kind: Literal[
        "validation",
        "too-large",
        "integration",
        "not-found",
        "conflict",
        "unavailable",
        "too-many-jobs",
        "method-not-allowed",
        "bad-host",
    ]
    field: str | None = Field(None, description="the request field at fault (dotted)")
    when: float | None = Field(None, description="integration failures: the time t at which it failed")
    why: str | None = Field(None, description="integration failures: the reason (IntegrationError)")
    method: str | None = None


# ----------------------------------------------------------------------------------------------
# pydantic's errors as the service's one-line answers
# ----------------------------------------------------------------------------------------------
WORK_FIELDS = {"t_end": "t_end", "samples": "output times", "times": "output times", "step": "step"}
"""Fields whose bound is a work limit of a request (413 with the hint to send a job, as the cost checks say)."""


def _bound_text(kind: str, ctx: dict[str, Any], value: Any) -> str | None:
    got = shown(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    if kind in ("greater_than_equal", "greater_than", "less_than_equal", "less_than") and ctx:
        op = {"greater_than_equal": ">=", "greater_than": ">", "less_than_equal": "<=", "less_than": "<"}[kind]
        bound = next(iter(ctx.values()))
        return (
            f"outside the allowed range: must be {op} {bound:g}, got {got}" if isinstance(bound, (int, float)) else None
        )
    return None


def describe_errors(errors: list[dict[str, Any]], *, where: str = "request") -> dict[str, Any]:
    """pydantic's validation errors as ``{"status", "kind", "field", "detail"}``: the first error, one line.

    The field is the dotted path in the request (a job's kind left out: ``params.grid``). A work bound
    (``t_end``, ``samples``, ``times``, ``step`` of ``POST /simulate`` or of a job's ``params``) is 413
    (``too-large``), as the cost checks answer, with the hint to send a request's work as a job;
    everything else is 422 (``validation``).
    """
    first = errors[0] if errors else {"loc": (), "msg": "invalid request", "type": "invalid"}
    raw = list(first.get("loc", ()))
    if raw and raw[0] in ("body", "query", "path"):
        raw = raw[1:]
    if where == "job" and len(raw) > 1 and raw[0] in JOB_KINDS:
        raw = raw[1:]
    loc = [str(x) for x in raw if str(x) not in UNION_TAGS]
    kind = str(first.get("type", ""))
    ctx = first.get("ctx") or {}
    if kind.startswith("union_tag"):
        loc.append(str(ctx.get("discriminator", "kind")).strip("'"))
    if kind == "json_invalid":  # the location is the byte offset of the error, not a field
        at = f" at position {loc[0]}" if loc and loc[0].isdigit() else ""
        loc = []
    loc = ["lambda" if x == "lambda_" else x for x in loc]
    field = ".".join(loc) or "body"
    msg = str(first.get("msg", "invalid")).replace("\n", " ")
    if kind == "json_invalid":
        msg = f"not valid JSON ({ctx.get('error', 'parse error')}{at})"
    else:
        msg = _bound_text(kind, ctx, first.get("input")) or msg
    more = f" (+{len(errors) - 1} more)" if len(errors) > 1 else ""
    name = loc[-1] if loc else ""
    at_top = loc == [name] if where == "request" else loc == ["params", name]
    over = kind in ("less_than_equal", "too_long") or (kind == "greater_than_equal" and name == "step")
    if at_top and name in WORK_FIELDS and over and where in ("request", "job"):
        limit = ctx.get("le", ctx.get("max_length", ctx.get("ge")))
        what = "at least" if kind == "greater_than_equal" else "at most"
        hint = "; send it as a job (POST /jobs with kind simulate or record)" if where == "request" else ""
        return {
            "status": 413,
            "kind": "too-large",
            "field": field,
            "detail": f"{field}: {what} {limit:g} ({WORK_FIELDS[name]}) in a {where}, got {_got(first.get('input'))}{hint}",
        }
    return {"status": 422, "kind": "validation", "field": field, "detail": f"{field}: {msg}{more}"}


def _got(value: Any) -> str:
    if isinstance(value, list):
        return f"{len(value)} values"
    return shown(value)
