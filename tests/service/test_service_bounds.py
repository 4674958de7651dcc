"""One input boundary: every numeric bound of the service's request schema is the library's bound.

The OpenAPI document's ``minimum`` / ``maximum`` (and exclusive ones) of every bounded numeric field of
every request model equal the bound the library names (:mod:`flatbody_env.physics.validation`, the
service's :class:`~flatbody_env.service.limits.Limits` for work, :class:`analysis.stationary.SearchBox`);
and the library's own checks refuse just beyond those named bounds and accept them.
"""

from __future__ import annotations

import math

import pytest

from analysis.families import follow_family
from analysis.stationary import SearchBox
from flatbody_env.integrators.base import Tolerances
from flatbody_env.physics import validation as v
from flatbody_env.physics.body import Body, default_body
from flatbody_env.physics.state import validate_state
from flatbody_env.scene import load_scene
from flatbody_env.service import models
from flatbody_env.service.app import create_app
from flatbody_env.service.limits import DEFAULT_LIMITS as L
from flatbody_env.service.limits import LimitExceeded, check_integration_cost

CONSTANTS = ("J", "J1", "J2", "J3", "k", "c", "d", "kappa", "a", "b")
STRETCHES = ("lambda", "mu", "rho", "lam_range", "mu_range")
MOMENTA = ("s1", "s2", "s3", "p_theta", "p_lambda", "p_mu", "p_rho", "theta", "spin", "from", "to")


def library_bound(model: str, field: str) -> tuple:
    """(low, low exclusive, high, high exclusive) the library states for ``field`` of request ``model``."""
    job = "Job" in model
    t_max = L.job_t_end if job else L.sync_t_end
    if field in CONSTANTS:
        return (v.PARAM_RANGE[0], False, v.PARAM_RANGE[1], False)
    if field in STRETCHES:
        return (v.STRETCH_RANGE[0], False, v.STRETCH_RANGE[1], False)
    if field in MOMENTA:
        return (-v.MOMENTUM_MAX, False, v.MOMENTUM_MAX, False)
    if field in ("rtol", "atol"):
        return (v.TOL_RANGE[0], False, v.TOL_RANGE[1], False)
    if field == "t_end":
        return (0.0, True, t_max, False)
    if field == "times":
        return (0.0, False, t_max, False)
    if field == "samples":
        return (v.MIN_SAMPLES, False, L.job_samples if job else L.sync_samples, False)
    if field == "step" and model == "FamilyJobParams":  # a continuation step: at most the width of the widest range
        return (0.0, True, 2 * v.MOMENTUM_MAX, False)
    if field == "step":  # t_end / step within the step limit for any t_end
        return (t_max / (L.job_steps if job else L.sync_steps), False, t_max, False)
    if field == "grid" and model == "StabilityMapJobParams":
        return (v.SWEEP_GRID_RANGE[0], False, L.job_map_grid, False)
    if field == "grid":
        return (v.SEARCH_GRID_RANGE[0], False, min(L.sync_grid, v.SEARCH_GRID_RANGE[1]), False)
    if field == "seeds":
        return (v.FAMILY_SEEDS_RANGE[0], False, min(L.job_family_seeds, v.FAMILY_SEEDS_RANGE[1]), False)
    if field == "episodes":
        return (1, False, L.job_episodes, False)
    if field == "seed":
        return (0, False, v.MAX_SEED, False)
    if field == "tensor_every":
        return (1, False, v.MAX_SAMPLES, False)
    raise AssertionError(f"{model}.{field}: a bounded field the library names no bound for")


def _numeric_bounds(node) -> list[tuple]:
    """Every (low, low exclusive, high, high exclusive) of a numeric schema under ``node`` (anyOf, items, prefixItems)."""
    found = []
    if isinstance(node, dict):
        if node.get("type") in ("number", "integer") and any(
            k in node for k in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")
        ):
            lo_x, hi_x = "exclusiveMinimum" in node, "exclusiveMaximum" in node
            found.append(
                (
                    node.get("exclusiveMinimum" if lo_x else "minimum", -math.inf),
                    lo_x,
                    node.get("exclusiveMaximum" if hi_x else "maximum", math.inf),
                    hi_x,
                )
            )
        for key in ("anyOf", "prefixItems"):
            for sub in node.get(key, ()):
                found += _numeric_bounds(sub)
        if "items" in node:
            found += _numeric_bounds(node["items"])
    return found


def _request_models() -> list[str]:
    todo, names = [models._Strict], []
    while todo:
        for sub in todo.pop().__subclasses__():
            names.append(sub.__name__)
            todo.append(sub)
    return names


@pytest.fixture(scope="module")
def schemas(tmp_path_factory):
    return create_app(tmp_path_factory.mktemp("bounds-data"), workers=1).openapi()["components"]["schemas"]


def test_every_bounded_request_field_states_the_library_bound(schemas):
    checked = 0
    for model in _request_models():
        for field, prop in schemas[model].get("properties", {}).items():
            for bound in _numeric_bounds(prop):
                assert bound == library_bound(model, field), f"{model}.{field}"
                checked += 1
    assert checked > 60  # every model was reached (the constants, the state, the settings of each request and job)


def test_defaults_are_the_library_defaults(schemas):
    box = SearchBox()
    assert schemas["SpinsRequest"]["properties"]["lam_range"]["default"] == list(box.lam)
    assert schemas["FamilyJobParams"]["properties"]["mu_range"]["default"] == list(box.mu)
    assert schemas["SpinsRequest"]["properties"]["grid"]["default"] == box.n
    assert schemas["SimulateRequest"]["properties"]["rtol"]["default"] == Tolerances().rtol
    assert schemas["RecordJobParams"]["properties"]["atol"]["default"] == Tolerances().atol
    assert default_body().to_dict() == models.DEFAULT_BODY


def _refuses(check, value) -> bool:
    try:
        check(value)
    except (ValueError, LimitExceeded):
        return True
    return False


def _body_with(field: str, x: float) -> Body:
    data = default_body().to_dict()
    if field in ("J1", "J2"):
        data["params"] = {"J1": 1.0, "J2": 1.0, "J3": 1.0, field: x}
    elif field in ("J", "J3"):
        data["params"][field] = x
    elif field in ("a", "b"):
        data["thickness"][field] = x
    else:
        data["potential"] = {
            "k": {"name": "V1", "k": x},
            "c": {"name": "V2", "c": x, "d": 1.0},
            "d": {"name": "V2", "c": 1.0, "d": x},
            "kappa": {"name": "V3", "kappa": x},
        }[field]
    return Body.from_dict(data)


def _state_with(field: str, x: float) -> None:
    state = dict(load_scene("default").state, **{field: x})
    if field in ("lambda", "mu") and state["lambda"] == state["mu"]:
        state["mu" if field == "lambda" else "lambda"] = 2.0 * x
    validate_state(state)


def _float_probe(name, check, low, high):
    assert not _refuses(check, low) and not _refuses(check, high), name
    assert _refuses(check, math.nextafter(low, -math.inf)) and _refuses(check, math.nextafter(high, math.inf)), name


@pytest.mark.parametrize("field", CONSTANTS + ("lambda", "mu", "rho") + MOMENTA[:8] + ("rtol",))
def test_the_library_refuses_just_beyond_its_named_ranges(field):
    low, _, high, _ = library_bound("SimulateRequest", field)
    if field in CONSTANTS:
        check = lambda x: _body_with(field, x)  # noqa: E731
    elif field == "rtol":
        check = lambda x: Tolerances(rtol=x)  # noqa: E731
    else:
        check = lambda x: _state_with(field, x)  # noqa: E731
    _float_probe(field, check, low, high)


@pytest.mark.parametrize("in_job", [False, True])
def test_the_work_limits_are_the_cost_checks(in_job):
    model = "SimulateJobParams" if in_job else "SimulateRequest"
    _, _, t_max, _ = library_bound(model, "t_end")
    assert not _refuses(lambda t: check_integration_cost(t_end=t, samples=2, step=None, in_job=in_job), t_max)
    assert _refuses(
        lambda t: check_integration_cost(t_end=t, samples=2, step=None, in_job=in_job), math.nextafter(t_max, math.inf)
    )
    _, _, n_max, _ = library_bound(model, "samples")
    assert not _refuses(lambda n: check_integration_cost(t_end=1.0, samples=n, step=None, in_job=in_job), n_max)
    assert _refuses(lambda n: check_integration_cost(t_end=1.0, samples=n, step=None, in_job=in_job), n_max + 1)
    h_min, _, _, _ = library_bound(model, "step")
    assert not _refuses(lambda h: check_integration_cost(t_end=t_max, samples=2, step=h, in_job=in_job), h_min)
    assert _refuses(
        lambda h: check_integration_cost(t_end=t_max, samples=2, step=h, in_job=in_job), math.nextafter(h_min, 0.0)
    )


def test_the_analysis_refuses_beyond_the_named_grid_and_seeds():
    lo, hi = v.SEARCH_GRID_RANGE
    SearchBox(n=lo), SearchBox(n=hi)
    for n in (lo - 1, hi + 1):
        with pytest.raises(ValueError, match="box.n"):
            SearchBox(n=n)
    body = default_body()
    for seeds in (v.FAMILY_SEEDS_RANGE[0] - 1, v.FAMILY_SEEDS_RANGE[1] + 1):
        with pytest.raises(ValueError, match="seeds"):
            follow_family(body, "s3", 0.05, 4.0, seeds=seeds)
