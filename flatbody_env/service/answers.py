"""What the service computes: validated request data in, the ``flatbody`` command's JSON answer out.

Every function here calls the very function the command's handler prints
(:mod:`flatbody_env.cli.simulate`, :mod:`flatbody_env.cli.analysis`), so an endpoint answers with
the command's keys and numbers. The functions run in worker processes (never in the event loop);
:func:`outcome` wraps one call so that its result or its error crosses the process boundary as
plain data.

Scenes given by name are looked up among the built-in scenes only: a request never names a file
on the server.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from flatbody_env.service.limits import DEFAULT_LIMITS, LimitExceeded, Limits, check_integration_cost

LIMITS = DEFAULT_LIMITS.with_environment()
"""The limits of this process: the defaults with any ``FLATBODY_LIMIT_<NAME>`` variable applied (worker processes
inherit the service's environment)."""


def _prefixed(where: str, exc: ValueError) -> ValueError:
    return ValueError(f"{where}.{exc}" if not str(exc).startswith(where) else str(exc))


def build_body(data: Mapping[str, Any], *, where: str = "body"):
    """A :class:`~flatbody_env.physics.body.Body` for the analysis (J1 = J2) from its JSON form.

    Raises
    ------
    ValueError
        Naming the field (``body.params.J``, …) and the allowed range.
    """
    from flatbody_env.physics.body import Body

    body = Body.from_dict(data, where=where)
    if not body.inertia.is_isotropic:
        raise ValueError(f"{where}.params: the analysis needs an isotropic body (J1 = J2)")
    return body


def build_scene(scene: str | Mapping[str, Any]):
    """A scene from its JSON object or the name of a built-in scene (never a path on the server)."""
    from flatbody_env.scene import builtin_scenes, scene_from_dict

    if isinstance(scene, str):
        scenes = builtin_scenes()
        if scene not in scenes:
            raise ValueError(f"scene: no built-in scene named {scene[:60]!r} (built-in: {', '.join(scenes)})")
        return scenes[scene]
    try:
        return scene_from_dict(scene)
    except ValueError as exc:
        raise _prefixed("scene", exc) from None


def _box(p: Mapping[str, Any]):
    from analysis.stationary import SearchBox

    return SearchBox(lam=tuple(p["lam_range"]), mu=tuple(p["mu_range"]), n=int(p["grid"]))


def ellipses(p: Mapping[str, Any]) -> dict[str, Any]:
    """``POST /ellipses``: the ``flatbody ellipses --json`` answer."""
    from flatbody_env.answers import ellipses_answer

    body = build_body(p["body"])
    return ellipses_answer(body, p["s3"], p["p_theta"], box=_box(p), branch=p["branch"], spin=p["spin"])


def stability(p: Mapping[str, Any]) -> dict[str, Any]:
    """``POST /stability``: the ``flatbody stability --json`` answer."""
    from flatbody_env.answers import stability_answer

    body = build_body(p["body"])
    return stability_answer(body, p["s3"], p["p_theta"], box=_box(p), branch=p["branch"], spin=p["spin"])


def trajectory(
    p: Mapping[str, Any],
    *,
    in_job: bool,
    with_rotation: bool | None = None,
    limits: Limits | None = None,
    max_nfev: int | None = None,
):
    """The :class:`~flatbody_env.simulation.Trajectory` of ``flatbody simulate`` for request ``p``,
    after checking its cost against ``limits`` (request or job limits). ``max_nfev``: the integration's budget of
    right-hand-side evaluations (None: the library's default; :func:`check_integration` passes 1)."""
    from flatbody_env.answers import simulate_trajectory

    limits = limits or LIMITS
    scene = build_scene(p["scene"])
    t_end = p.get("t_end") or scene.t_end
    samples = _sample_count(p)
    check_integration_cost(t_end=t_end, samples=samples, step=p.get("step"), in_job=in_job, limits=limits)
    try:
        return scene, simulate_trajectory(
            scene,
            t_end=p.get("t_end"),
            times=p.get("times"),
            samples=p.get("samples"),
            method=p["method"],
            rtol=p["rtol"],
            atol=p["atol"],
            step=p.get("step"),
            model=p["model"],
            with_rotation=p.get("with_rotation", False) if with_rotation is None else with_rotation,
            max_wall_time=limits.job_seconds if in_job else limits.request_seconds,
            max_nfev=max_nfev,
        )
    except (
        ValueError
    ) as exc:  # a method's refusal of the scene's body (J1 = J2, V2 with c = d, ...) names the request's field
        if str(exc).split(":", 1)[0].split(".", 1)[0] in _SCENE_FIELDS:
            raise _prefixed("scene", exc) from None
        raise


def _sample_count(p: Mapping[str, Any]) -> int:
    """How many output times request ``p`` asks for: its ``times``, its ``samples``, else the library's
    :data:`~flatbody_env.simulation.DEFAULT_SAMPLES` (the cost check counts them before the integration)."""
    from flatbody_env.simulation import DEFAULT_SAMPLES

    times = p.get("times")
    return len(times) if times else (p.get("samples") or DEFAULT_SAMPLES)


_SCENE_FIELDS = ("params", "potential", "thickness", "state", "spin_convention")
"""Fields of a scene that an integrator's refusal may name (a request names them under ``scene.``)."""


def simulate(p: Mapping[str, Any]) -> dict[str, Any]:
    """``POST /simulate``: the ``flatbody simulate`` JSON (``Trajectory.to_dict()``)."""
    return trajectory(p, in_job=False)[1].to_dict()


def invariants(p: Mapping[str, Any]) -> dict[str, Any]:
    """``POST /invariants``: the ``flatbody invariants --json`` answer for a trajectory dict."""
    from flatbody_env.answers import invariants_answer

    body = build_body(p["body"]) if p.get("body") is not None else None
    data = {k: v for k, v in p.items() if k != "body" and v is not None}
    return invariants_answer(data, body)


def scenes(_: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``GET /scenes``: the ``flatbody scenes --json`` answer."""
    from flatbody_env.answers import scenes_answer

    return scenes_answer()


def methods(_: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """``GET /methods``: the ``flatbody methods --json`` answer."""
    from flatbody_env.answers import methods_answer

    return methods_answer()


def _check_family_range(params: Mapping[str, Any]) -> None:
    """A family's range in the request's own words (``from``, ``to``): from < to, and a body constant's range
    within the constant's allowed bounds (:func:`analysis.families.check_range`) — refused when the job is
    submitted, not when it runs."""
    from analysis.families import BODY_PARAMETERS, body_with, check_range

    check_range(params["vary"], params["from"], params["to"], names=("from", "to"))
    if params["vary"] in BODY_PARAMETERS:
        try:
            body_with(build_body(params["body"]), params["vary"], params["from"])
        except ValueError as exc:
            if str(exc).startswith("body"):
                raise
            raise ValueError(f"vary: {str(exc).split(': ', 1)[-1]}") from None


def check_integration(p: Mapping[str, Any], *, with_rotation: bool | None = None) -> None:
    """Refuse a ``simulate`` or ``record`` job's params as its work would, before it is queued: the job's own
    integration (:func:`trajectory`, with the job limits) run with a budget of one right-hand-side evaluation. Every
    check of the integration runs first, as in the job (the scene, the cost, ``times`` or ``samples`` and the output
    times within [0, t_end], the method's name and chart against ``model``, ``step`` for fixed-step methods only, the
    method's refusals of the body); then the budget stops it at its first evaluation, so nothing is integrated.

    Raises
    ------
    ValueError, LimitExceeded
        As the job would, naming the field.
    """
    from contextlib import suppress

    from flatbody_env.integrators import IntegrationError

    # stopped by the budget (or failed at its first step, as the job then would): every check has passed
    with suppress(IntegrationError):
        trajectory(p, in_job=True, with_rotation=with_rotation, max_nfev=1)


def _check_map_ranges(params: Mapping[str, Any]) -> None:
    """A stability map's ranges hold a shape with lambda > mu (the only shapes the map draws,
    :func:`analysis.families.shape_stability_grid`): otherwise the job finds no row and its chart fails."""
    (lam_lo, lam_hi), (mu_lo, mu_hi) = params["lam_range"], params["mu_range"]
    if not lam_hi > mu_lo:
        raise ValueError(
            f"lam_range: the map draws the shapes with lambda > mu only, so HI of lam_range must exceed LO of "
            f"mu_range ({mu_lo:g}); got lam_range [{lam_lo:g}, {lam_hi:g}], mu_range [{mu_lo:g}, {mu_hi:g}]"
        )


def check_job(p: Mapping[str, Any]) -> dict[str, Any]:
    """Check a job (``{"kind", "params"}``) before it is queued, by the checks its work runs: a family's range, a map's
    ranges, the body, a scene job's integration settings and cost (:func:`check_integration`); ``{}`` if fine. So a
    value the work would refuse is a 422 naming the field, never a queued job that fails in its worker.

    Raises
    ------
    ValueError, LimitExceeded
        Naming the field under ``params.``.
    """
    params = p["params"]
    try:
        if p.get("kind") == "family":
            _check_family_range(params)
        if p.get("kind") == "stability-map":
            _check_map_ranges(params)
        if "body" in params:
            build_body(params["body"])
        if "scene" in params:
            # a record job integrates R(t) too (jobs._record); a simulate job as its params say
            check_integration(params, with_rotation=True if p.get("kind") == "record" else None)
    except LimitExceeded as exc:
        raise LimitExceeded(f"params.{exc.field}", str(exc).split(": ", 1)[1]) from None
    except ValueError as exc:
        text = _first_line(exc)
        raise ValueError(f"params.{text}" if _field_of(text) else f"params: {text}") from None
    return {}


def invariants_json(body: bytes) -> dict[str, Any]:
    """``POST /invariants`` from its raw body: parsed and checked here (a worker process), not in the event loop."""
    from pydantic import ValidationError

    from flatbody_env.service.models import TrajectoryRequest, describe_errors

    try:
        request = TrajectoryRequest.model_validate_json(body)
    except ValidationError as exc:
        raise RequestInvalid(describe_errors(exc.errors(include_url=False), where="other")) from None
    payload = request.trajectory()
    payload["body"] = request.body.as_data() if request.body is not None else None
    return invariants(payload)


class RequestInvalid(ValueError):
    """A request body that breaks its model (checked in a worker process): ``data`` is the error answer."""

    def __init__(self, data: dict[str, Any]) -> None:
        super().__init__(data["detail"])
        self.data = data


ANSWERS: dict[str, Callable[[Mapping[str, Any]], Any]] = {
    "scenes": scenes,
    "methods": methods,
    "check-job": check_job,
    "ellipses": ellipses,
    "stability": stability,
    "simulate": simulate,
    "invariants": invariants,
    "invariants-json": invariants_json,
}
"""Request-path computations by endpoint name."""


INPUT_FIELDS = {
    "simulate": "scene",
    "ellipses": "body",
    "stability": "body",
    "invariants": "trajectory",
    "invariants-json": "trajectory",
    "check-job": "params",
}
"""The request field an endpoint computes with, named by a refusal that no narrower field explains: a failed integration
(the scene's trajectory), a computation that fails for these inputs. An HTTP 4xx always names a field."""


def _first_line(exc: BaseException) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _field_of(text: str) -> str | None:
    """The dotted field a one-line message starts with (``body.params.J: ...``), or None."""
    head = text.split(":", 1)[0]
    return head if ":" in text and head and " " not in head else None


def error_data(exc: BaseException, *, endpoint: str | None = None) -> dict[str, Any]:
    """An exception as the service's error answer (:class:`~flatbody_env.service.models.ErrorAnswer`), one line naming the
    field: the exception's own, else that of ``endpoint`` (:data:`INPUT_FIELDS`). A used-up integration budget names
    ``t_end`` (the horizon the work did not reach; a job has larger budgets)."""
    from flatbody_env.integrators import IntegrationError

    if isinstance(exc, RequestInvalid):
        return dict(exc.data)
    where = INPUT_FIELDS.get(endpoint or "")
    if isinstance(exc, IntegrationError):
        # a used-up work budget is a request over the limits (413); any other failure is the integration's (422)
        budget = exc.kind == "budget"
        field = ("t_end" if budget else where) if where else None
        text = _first_line(exc)
        if field == "t_end":
            text = f"t_end: not reached within this request's budget ({text}); send it as a job (POST /jobs with kind simulate or record)"
        elif field:
            text = f"{field}: {text}"
        return {
            "kind": "too-large" if budget else "integration",
            "detail": text,
            "field": field,
            "when": exc.t if math.isfinite(exc.t) else None,
            "why": exc.reason,
            "method": exc.method or None,
        }
    if isinstance(exc, LimitExceeded):
        return {"kind": "too-large", "detail": str(exc), "field": exc.field}
    if isinstance(exc, OSError):  # a job's file could not be written (disk full, file-size limit): the server's fault
        text = " ".join(str(exc).split())[:200] or type(exc).__name__
        return {"kind": "unavailable", "detail": f"the service could not write the job's files ({text})", "status": 503}
    if isinstance(exc, ValueError):
        text = _first_line(exc)
        field = _field_of(text)
        if field and field.startswith(
            "-"
        ):  # a check shared with the CLI names its flag (--spin): name the request's field
            text = field.lstrip("-").replace("-", "_") + text[len(field) :]
            field = field.lstrip("-").replace("-", "_")
        if field is None and where:  # a numerical failure (numpy's LinAlgError is a ValueError), not a check of a field
            field, text = (
                where,
                f"{where}: the computation failed for these inputs ({type(exc).__name__}: {text[:200]})",
            )
        return {"kind": "validation", "detail": text, "field": field}
    # Anything else is a computation that cannot be done for these inputs (a singular matrix, an
    # overflow, ...): the caller gets one line, never a traceback.
    text = f"the computation failed for these inputs ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})"
    return {"kind": "validation", "detail": f"{where}: {text}" if where else text, "field": where}


def outcome(name: str, payload: Mapping[str, Any]) -> tuple[bool, Any]:
    """Run ``ANSWERS[name](payload)``: ``(True, answer)`` or ``(False, error_data)`` (picklable either way)."""
    try:
        return True, ANSWERS[name](payload)
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line for the caller
        return False, error_data(exc, endpoint=name)


def outcome_json(name: str, payload: Any) -> tuple[bool, Any]:
    """:func:`outcome` with the answer rendered here as JSON bytes (NaN/inf as null): ``(True, bytes)`` or
    ``(False, error_data)``. The event loop then only passes the bytes on."""
    from flatbody_env.service.store import finite_json

    ok, data = outcome(name, payload)
    if not ok:
        return ok, data
    try:
        return True, finite_json(data).encode("utf-8")
    except (TypeError, ValueError, RecursionError) as exc:
        return False, error_data(exc, endpoint=name)


def warm_up() -> bool:
    """Import the analysis stack in a fresh worker process (so that the first request is not slow)."""
    import analysis.stability  # noqa: F401
    import flatbody_env.simulation  # noqa: F401

    return True


__all__ = [
    "ANSWERS",
    "INPUT_FIELDS",
    "LIMITS",
    "RequestInvalid",
    "build_body",
    "build_scene",
    "check_integration",
    "check_job",
    "ellipses",
    "error_data",
    "invariants",
    "invariants_json",
    "methods",
    "outcome",
    "outcome_json",
    "scenes",
    "simulate",
    "stability",
    "trajectory",
    "warm_up",
]
