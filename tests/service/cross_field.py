"""The service's refusals that its OpenAPI document cannot state: each with a witness request.

A witness is a request that the document allows (checked against it in ``test_cross_field.py``) and that the
service refuses with the status given, naming the field. :data:`CROSS_FIELD` — the fields the schemathesis
test accepts as refused for reasons beyond the schema — is derived from the witnesses, so every field in it is
shown to be a real refusal; a refusal that schemathesis finds with a field not listed here fails that test.
"""

from __future__ import annotations

BODY = {"params": {"J": 1.0, "J3": 1.0}, "potential": {"name": "V3", "kappa": 1.0}, "thickness": {"a": 1.0, "b": 1.0}}
ANISOTROPIC = {**BODY, "params": {"J1": 1.0, "J2": 2.0, "J3": 1.0}}
STATE = {
    "s1": 0.0,
    "s2": 0.0,
    "s3": 0.5,
    "p_theta": 0.1,
    "p_lambda": 0.0,
    "p_mu": 0.0,
    "p_rho": 0.0,
    "lambda": 1.2,
    "mu": 0.8,
    "rho": 1.0,
    "theta": 0.0,
}
SCENE = {**BODY, "state": STATE}
ON_THE_CIRCLE = {**BODY, "state": {**STATE, "mu": 1.2}}
ANALYSIS = {"body": BODY, "s3": 0.5, "p_theta": 0.1}

WITNESSES = [
    # (field named, status, path, request, what the schema cannot say)
    ("times", 422, "/simulate", {"times": [2.0, 1.0]}, "output times strictly increasing"),
    ("times", 422, "/simulate", {"t_end": 1.0, "times": [0.0, 2.0]}, "output times within [0, t_end]"),
    ("times", 422, "/simulate", {"times": [0.0, 1.0], "samples": 5}, "times or samples, not both"),
    ("t_end", 413, "/simulate", {"scene": "long-horizon"}, "a built-in scene's own t_end over the request limit"),
    ("scene.state.lambda", 422, "/simulate", {"scene": ON_THE_CIRCLE}, "lambda != mu"),
    (
        "params.scene.state.lambda",
        422,
        "/jobs",
        {"kind": "simulate", "params": {"scene": ON_THE_CIRCLE}},
        "lambda != mu",
    ),
    (
        "scene.params",
        422,
        "/simulate",
        {"scene": {**SCENE, "params": ANISOTROPIC["params"]}, "method": "splitting-strang", "step": 0.01},
        "a splitting needs J1 = J2",
    ),
    (
        "scene.potential",
        422,
        "/simulate",
        {"scene": {**SCENE, "potential": {"name": "V2", "c": 1.0, "d": 2.0}}, "method": "RATTLE", "step": 0.01},
        "RATTLE needs V2 with c = d",
    ),
    (
        "scene.spin_convention",
        422,
        "/simulate",
        {"scene": {**SCENE, "spin_convention": "paper"}, "model": "regular"},
        "the regular model is the corrected convention",
    ),
    ("method", 422, "/simulate", {"method": "no-such-method"}, "a method's name (GET /methods)"),
    ("method", 422, "/simulate", {"model": "regular", "method": "RK4", "step": 0.01}, "a method of the model's chart"),
    ("params.method", 422, "/jobs", {"kind": "simulate", "params": {"method": "no-such-method"}}, "a method's name"),
    (
        "params.times",
        422,
        "/jobs",
        {"kind": "simulate", "params": {"times": [0.0, 1.0], "samples": 5}},
        "times or samples, not both",
    ),
    (
        "params.step",
        422,
        "/jobs",
        {"kind": "record", "params": {"step": 0.01}},
        "method auto chooses its own step",
    ),
    (
        "params.scene.spin_convention",
        422,
        "/jobs",
        {"kind": "simulate", "params": {"scene": {**SCENE, "spin_convention": "paper"}, "model": "regular"}},
        "the regular model is the corrected convention",
    ),
    (
        "params.scene.params",
        422,
        "/jobs",
        {
            "kind": "simulate",
            "params": {"scene": {**SCENE, "params": ANISOTROPIC["params"]}, "method": "splitting-strang", "step": 0.01},
        },
        "a splitting needs J1 = J2",
    ),
    (
        "params.scene.potential",
        422,
        "/jobs",
        {
            "kind": "simulate",
            "params": {
                "scene": {**SCENE, "potential": {"name": "V2", "c": 1.0, "d": 2.0}},
                "method": "RATTLE",
                "step": 0.01,
            },
        },
        "RATTLE needs V2 with c = d",
    ),
    ("step", 422, "/simulate", {"method": "RK4"}, "a fixed-step method needs a step"),
    ("step", 422, "/simulate", {"method": "DOP853", "step": 0.01}, "an adaptive method takes no step"),
    ("body.params", 422, "/ellipses", {**ANALYSIS, "body": ANISOTROPIC}, "the analysis needs J1 = J2"),
    ("body.params", 422, "/stability", {**ANALYSIS, "body": ANISOTROPIC}, "the analysis needs J1 = J2"),
    (
        "params.body.params",
        422,
        "/jobs",
        {"kind": "family", "params": {"body": ANISOTROPIC}},
        "the analysis needs J1 = J2",
    ),
    ("spin", 422, "/ellipses", {**ANALYSIS, "branch": "A"}, "branch A needs a spin"),
    ("lam_range", 422, "/ellipses", {**ANALYSIS, "lam_range": [2.0, 1.0]}, "a search range's LO < HI"),
    ("mu_range", 422, "/stability", {**ANALYSIS, "mu_range": [2.0, 1.0]}, "a search range's LO < HI"),
    (
        "params.lam_range",
        422,
        "/jobs",
        {"kind": "family", "params": {"lam_range": [2.0, 1.0]}},
        "a search range's LO < HI",
    ),
    (
        "params.mu_range",
        422,
        "/jobs",
        {"kind": "stability-map", "params": {"mu_range": [2.0, 1.0]}},
        "a search range's LO < HI",
    ),
    ("params.to", 422, "/jobs", {"kind": "family", "params": {"from": 2.0, "to": 1.0}}, "a family's from < to"),
    (
        "params.from",
        422,
        "/jobs",
        {"kind": "family", "params": {"vary": "kappa", "from": 0.0, "to": 1.0}},
        "a body constant stays > 0",
    ),
    (
        "params.vary",
        422,
        "/jobs",
        {
            "kind": "family",
            "params": {
                "vary": "kappa",
                "from": 0.5,
                "to": 1.0,
                "body": {**BODY, "potential": {"name": "V1", "k": 1.0}},
            },
        },
        "a constant of this body's potential",
    ),
]

_TRAJECTORY = {"t": [0.0, 1.0], "state": {k: [v, v] for k, v in STATE.items()}}

PREFIX_WITNESSES = [
    # POST /invariants checks a trajectory's content (its state's entries, times, meta) beyond its schema: every such
    # refusal names a field under ``trajectory.``
    ("trajectory.", "trajectory.t", 422, "/invariants", {**_TRAJECTORY, "t": [1.0, 0.0]}, "times strictly increasing"),
    ("trajectory.", "trajectory.state.s1", 422, "/invariants", {"t": [0.0], "state": {}}, "every state entry present"),
    (
        "trajectory.",
        "trajectory.meta.model",
        422,
        "/invariants",
        {**_TRAJECTORY, "meta": {"model": 3}},
        "meta's entries typed",
    ),
]

CROSS_FIELD = frozenset(field for field, *_ in WITNESSES)
"""Fields refused for reasons beyond the schema, each shown by a witness in :data:`WITNESSES`."""
CROSS_FIELD_PREFIXES = tuple(sorted({prefix for prefix, *_ in PREFIX_WITNESSES}))
"""Prefixes of such fields (a trajectory's content), each shown by witnesses in :data:`PREFIX_WITNESSES`."""
