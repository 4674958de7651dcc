"""A hostile corpus for the HTTP service, the oracle that judges its answers, and a runner that tallies them.

Used by ``tests/fuzz/test_fuzz_http.py`` (hypothesis draws from the same field table and values) and as a
probe against a running service (``python tests/fuzz/http_corpus.py URL``), which prints the tally.

Every case is one request to a real ``flatbody serve`` on loopback: one field of an endpoint's valid body
replaced by a hostile value (NaN/±inf as JSON tokens and as strings, 1e±308, 1e999, 400-digit integers,
wrong types, unicode, huge strings and arrays, deep nesting, integral and fractional floats), plus broken
bodies (empty, truncated, duplicate keys, over the size limit), hostile query strings and job ids, bad
``Host`` headers and unsupported methods. :func:`judge` says what is wrong with an answer:

* ``5xx``: any 5xx but a documented 503 (``kind`` ``unavailable``);
* ``hang``: no answer within the per-request timeout;
* ``silent-accept``: a 2xx answer to a value outside the field's documented bounds (:data:`FIELDS`);
* ``unnamed``: a 4xx that is not one JSON line with a ``field`` (405: with ``Allow``; an integration failure:
  with ``when`` and ``why``), or names a field unrelated to the one sent (``misnamed``);
* tracebacks in the server's log are counted by the runner of the service (:func:`start_service`).
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flatbody_env.service.models import BUILTIN_SCENES  # noqa: E402 - the names GET /scenes lists
from flatbody_env.service.launch import stop_service  # noqa: E402

BODY = {"params": {"J": 1.0, "J3": 1.0}, "potential": {"name": "V1", "k": 1.0}, "thickness": {"a": 1.0, "b": 1.0}}
SCENE = {
    "params": {"J": 1.0, "J3": 1.0},
    "potential": {"name": "V3", "kappa": 1.0},
    "thickness": {"a": 1.0, "b": 1.0},
    "state": {
        "s1": 0.0,
        "s2": 0.0,
        "s3": 2.0,
        "p_theta": 0.5,
        "p_lambda": 0.0,
        "p_mu": 0.0,
        "p_rho": 0.0,
        "lambda": 1.5,
        "mu": 1.0,
        "rho": 1.0,
        "theta": 0.0,
    },
    "t_end": 0.5,
}

SMALL_LIMITS = {
    "FLATBODY_LIMIT_MAX_BODY_BYTES": "65536",
    "FLATBODY_LIMIT_MAX_TRAJECTORY_BODY_BYTES": "262144",
    "FLATBODY_LIMIT_REQUEST_SECONDS": "20",
    "FLATBODY_LIMIT_MAX_QUEUED_JOBS": "100000",
    "FLATBODY_LIMIT_MAX_QUEUED_PER_CLIENT": "100000",
    "FLATBODY_LIMIT_MAX_STORED_JOBS": "100000",
}
"""The service's limits in the fuzz run: small bodies (so oversized ones are cheap), no job quota in the way."""
MAX_BODY = int(SMALL_LIMITS["FLATBODY_LIMIT_MAX_BODY_BYTES"])


class Raw(str):
    """A JSON token written as is into the body (``NaN``, ``1e999``, ``263.0``, a deeply nested array, invalid JSON)."""


def parsed(value: Any) -> Any:
    """What the service's JSON parser makes of ``value`` (a :class:`Raw` token parsed; invalid JSON is :data:`INVALID`)."""
    if isinstance(value, Raw):
        try:
            return json.loads(value)
        except (ValueError, RecursionError):
            return INVALID
    return value


INVALID = object()
"""An unparseable token: the whole body is invalid JSON."""

DEEP = Raw("[" * 50_000 + "]" * 50_000)

# -- the documented bounds of every field (docs/service.md, the OpenAPI document) ------------------------------
CONST = ("num", 1e-6, 1e6)
MOMENTUM = ("num", -1e6, 1e6)
STRETCH = ("num", 1e-6, 1e6)
TOL = ("num", 1e-16, 1.0)


def num(lo, hi, *, gt=False, nullable=False):
    return ("num", lo, hi, gt, nullable)


def integer(lo, hi, *, nullable=False):
    return ("int", lo, hi, nullable)


def text(max_len, *, nullable=False):
    return ("str", max_len, nullable)


def enum(*values, nullable=False):
    return ("enum", values, nullable)


def boolean():
    return ("bool",)


def numbers(max_items, lo, hi, *, min_items=1, exact=None, nullable=False):
    return ("list", max_items, lo, hi, min_items, exact, nullable)


def c(spec):  # a constant / stretch / momentum / tolerance as a full spec
    return num(spec[1], spec[2])


SPINS = {
    "body.params.J": c(CONST),
    "body.params.J3": c(CONST),
    "body.potential.k": c(CONST),
    "body.thickness.a": c(CONST),
    "body.thickness.b": c(CONST),
    "body.potential.name": enum("V1", "V2", "V3"),
    "body.spin_convention": enum("corrected"),
    "body.params": ("obj",),
    "body": ("obj",),
    "s3": c(MOMENTUM),
    "p_theta": c(MOMENTUM),
    "spin": num(-1e6, 1e6, nullable=True),
    "branch": enum("N", "A", "all"),
    "grid": integer(8, 401),
    "lam_range": numbers(2, 1e-6, 1e6, exact=2),
    "mu_range": numbers(2, 1e-6, 1e6, exact=2),
}
SIMULATE_SCENE = {
    "scene.params.J": c(CONST),
    "scene.potential.kappa": c(CONST),
    "scene.thickness.b": c(CONST),
    "scene.state.lambda": c(STRETCH),
    "scene.state.rho": c(STRETCH),
    "scene.state.s3": c(MOMENTUM),
    "scene.state.theta": c(MOMENTUM),
    "scene.state.p_rho": c(MOMENTUM),
    "scene.name": text(64, nullable=True),
    "scene.description": text(2000, nullable=True),
    "scene.state": ("obj",),
    "scene.potential": ("obj",),
}


def simulate_fields(t_max, step_min, samples_max, prefix=""):
    out = {
        "t_end": num(0, t_max, gt=True, nullable=True),
        "samples": integer(2, samples_max, nullable=True),
        "times": numbers(2001, 0, t_max, nullable=True),
        "rtol": c(TOL),
        "atol": c(TOL),
        "step": num(step_min, t_max, nullable=True),
        "method": text(64),
        "model": enum("auto", "two-polar", "regular"),
        "scene": enum(*BUILTIN_SCENES),
    }
    return {prefix + k: v for k, v in out.items()}


@dataclass(frozen=True)
class Endpoint:
    name: str
    method: str
    path: str
    base: Any
    fields: dict[str, tuple]
    prefix: str = ""  # the error's field names start here (a job's params)


def endpoints(trajectory: dict | None = None) -> list[Endpoint]:
    """The endpoints with a JSON body, their valid base bodies and their fields' bounds."""
    sim = {"scene": "default", "t_end": 0.5, "samples": 11}
    out = [
        Endpoint("ellipses", "POST", "/ellipses", {"body": BODY, "s3": 2.0, "p_theta": 0.5, "grid": 8}, SPINS),
        Endpoint(
            "stability",
            "POST",
            "/stability",
            {"body": BODY, "s3": 2.0, "p_theta": 0.5, "grid": 8},
            {k: v for k, v in SPINS.items() if k in ("s3", "grid", "body.params.J", "lam_range")},
        ),
        Endpoint(
            "simulate", "POST", "/simulate", sim, {**simulate_fields(200, 1e-3, 2001), "with_rotation": boolean()}
        ),
        Endpoint("simulate-scene", "POST", "/simulate", {"scene": SCENE, "samples": 11}, SIMULATE_SCENE),
        Endpoint(
            "job-simulate",
            "POST",
            "/jobs",
            {"kind": "simulate", "params": {"scene": "default", "t_end": 1.0, "samples": 11}},
            {
                **simulate_fields(10_000, 5e-4, 20001, "params."),
                "kind": enum("simulate", "record", "family", "stability-map", "evaluate"),
                "params": ("obj",),
            },
        ),
        Endpoint(
            "job-record",
            "POST",
            "/jobs",
            {"kind": "record", "params": {"scene": "default", "t_end": 1.0, "samples": 11}},
            {
                "params.samples": integer(2, 20001),
                "params.tensor_every": integer(1, 100_000),
                "params.title": text(200, nullable=True),
                "params.t_end": num(0, 10_000, gt=True, nullable=True),
            },
        ),
        Endpoint(
            "job-family",
            "POST",
            "/jobs",
            {"kind": "family", "params": {"body": BODY, "vary": "s3", "from": 0.5, "to": 1.0, "seeds": 2, "grid": 8}},
            {
                "params.from": c(MOMENTUM),
                "params.to": c(MOMENTUM),
                "params.seeds": integer(2, 200),
                "params.grid": integer(8, 401),
                "params.step": num(0, 2e6, gt=True, nullable=True),
                "params.vary": enum("s3", "p_theta", "k", "c", "d", "kappa", "a", "b", "J", "J3"),
                "params.p_theta": num(-1e6, 1e6, nullable=True),
                "params.body.params.J3": c(CONST),
            },
        ),
        Endpoint(
            "job-map",
            "POST",
            "/jobs",
            {"kind": "stability-map", "params": {"body": BODY, "grid": 4}},
            {
                "params.grid": integer(4, 200),
                "params.lam_range": numbers(2, 1e-6, 1e6, exact=2),
                "params.body.thickness.a": c(CONST),
            },
        ),
        Endpoint(
            "job-evaluate",
            "POST",
            "/jobs",
            {"kind": "evaluate", "params": {"episodes": 1, "baselines": False}},
            {"params.episodes": integer(1, 1000), "params.seed": integer(0, 2**32 - 1), "params.baselines": boolean()},
        ),
    ]
    if trajectory is not None:
        out.append(
            Endpoint(
                "invariants",
                "POST",
                "/invariants",
                trajectory,
                {
                    "t": numbers(20001, -math.inf, math.inf),
                    "state.lambda": numbers(20001, -math.inf, math.inf, min_items=0),
                    "energy": numbers(20001, -math.inf, math.inf, min_items=0, nullable=True),
                    "meta": ("dict", 64, True),
                    "initial_state": ("dict", 16, True),
                    "state": ("dict", 16, False),
                    "rotation": ("any", True),
                },
            )
        )
    return out


# -- hostile values -----------------------------------------------------------------------------------------
NUMERIC = [
    Raw("NaN"),
    Raw("Infinity"),
    Raw("-Infinity"),
    "NaN",
    "inf",
    "-inf",
    "1",
    1e308,
    -1e308,
    Raw("1e999"),
    Raw("-1e999"),
    10**400,
    -(10**400),
    1e-308,
    0,
    -1,
    True,
    None,
    [],
    {},
    [1.0],
    "",
    "é中😀",
    Raw("263.0"),
    Raw("263.5"),
    Raw("1E2"),
    Raw("-0"),
    Raw("0x10"),
    Raw("01"),
]
TEXTUAL = [
    1,
    1.5,
    None,
    True,
    [],
    {},
    ["V1"],
    "",
    "é中😀\u0000",
    "\ud800",
    "x" * 65,
    "y" * 201,
    "z" * 2001,
    "../../etc/passwd",
    Raw("NaN"),
]
LISTS = [
    None,
    3.0,
    "1,2",
    [],
    [1.0],
    [1.0, 2.0, 3.0],
    [Raw("NaN"), 1.0],
    [1.0, Raw("Infinity")],
    [[1.0], [2.0]],
    ["1", "2"],
    [True, False],
    [1e308, -1e308],
    [0.5] * 2002,
    DEEP,
    {"0": 1.0},
]
OBJECTS = [None, 1, "x", [], [{}], {}, {"x": 1}, DEEP, Raw("NaN")]
HOSTILE_VALUES = {
    "num": NUMERIC,
    "int": NUMERIC,
    "str": TEXTUAL,
    "enum": TEXTUAL[:10] + ["V4", "n"],
    "bool": [0, 1, "true", None, [], Raw("NaN")],
    "list": LISTS,
    "obj": OBJECTS,
    "dict": OBJECTS + [{str(i): 1.0 for i in range(70)}],
    "any": OBJECTS,
}
"""The hostile values each kind of field gets in the fixed corpus."""


def in_bounds(value: Any, spec: tuple) -> bool:
    """Whether ``value`` (as parsed) is of the field's type and inside its documented bounds: then the service may
    accept or refuse it (another field, the computation); outside, it must refuse it."""
    value = parsed(value)
    if value is INVALID:
        return False
    kind = spec[0]
    nullable = (
        spec[-1]
        if kind in ("num", "int", "str", "enum", "list", "dict", "any") and isinstance(spec[-1], bool)
        else False
    )
    if value is None:
        return nullable
    if kind in ("num", "int"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if kind == "int" and not (isinstance(value, int) or (value.is_integer() and abs(value) < 2**53)):
            return False
        try:
            v = float(value)
        except OverflowError:
            return False
        if not math.isfinite(v):
            return False
        lo, hi = spec[1], spec[2]
        gt = kind == "num" and spec[3]
        return (v > lo if gt else v >= lo) and v <= hi
    if kind == "str":
        return isinstance(value, str) and len(value) <= spec[1]
    if kind == "enum":
        return isinstance(value, str) and value in spec[1]
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "list":
        _, max_items, lo, hi, min_items, exact, _ = spec
        if not isinstance(value, list) or not min_items <= len(value) <= max_items or (exact and len(value) != exact):
            return False
        return all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and lo <= v <= hi and _finite(v) for v in value
        )
    if kind == "dict":
        return isinstance(value, dict) and len(value) <= spec[1]
    return True  # obj / any: structure the oracle does not judge (a wrong one is refused, a right one may be accepted)


def _finite(v: int | float) -> bool:
    """A JSON number that is a finite float64 (an integer beyond float range is not)."""
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


# -- cases --------------------------------------------------------------------------------------------------
@dataclass
class Case:
    """One request and what a correct answer must be."""

    name: str
    method: str
    path: str
    body: bytes | None = None
    params: dict[str, str] | None = None
    headers: dict[str, str] = field(default_factory=dict)
    must_refuse: bool = False  # a 2xx is a silent accept
    sent_field: str | None = None  # the field the hostile value went to (the error must name it or a related one)
    expect: int | None = None  # an exact status (400 bad host, 405, 413)


def _encode(data: Any) -> bytes:
    raws: list[str] = []

    def walk(x):
        if isinstance(x, Raw):
            raws.append(str(x))
            return f"\x00RAW{len(raws) - 1}\x00"
        if isinstance(x, dict):
            return {k: walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x

    text = json.dumps(walk(data))
    for i, raw in enumerate(raws):
        text = text.replace(json.dumps(f"\x00RAW{i}\x00"), raw, 1)
    return text.encode("utf-8", "surrogatepass")


def _with(base: Any, path: str, value: Any) -> Any:
    data = json.loads(json.dumps(base))
    keys = path.split(".")
    node = data
    for key in keys[:-1]:
        node = node[key]
    node[keys[-1]] = value
    return data


def field_case(ep: Endpoint, path: str, value: Any) -> Case:
    spec = ep.fields[path]
    body = _with(ep.base, path, value)
    return Case(
        f"{ep.name}:{path}={_short(value)}",
        ep.method,
        ep.path,
        _encode(body),
        headers={"content-type": "application/json"},
        must_refuse=not in_bounds(value, spec),
        sent_field=path,
    )


def _short(value: Any) -> str:
    text = str(value) if isinstance(value, Raw) else json.dumps(value, default=str)
    return text if len(text) <= 24 else f"{text[:12]}…({len(text)})"


def fixed_cases(trajectory: dict | None = None) -> list[Case]:
    """The fixed corpus: every field of every endpoint with every hostile value of its kind, and the raw cases."""
    cases = []
    for ep in endpoints(trajectory):
        for path, spec in ep.fields.items():
            for value in HOSTILE_VALUES[spec[0]]:
                cases.append(field_case(ep, path, value))
    return cases + raw_cases()


def raw_cases() -> list[Case]:
    json_ct = {"content-type": "application/json"}
    out = []
    for path in ("/ellipses", "/stability", "/simulate", "/invariants", "/jobs"):
        for name, body in (
            ("empty", b""),
            ("truncated", b'{"s3": 2'),
            ("null", b"null"),
            ("list", b"[]"),
            ("number", b"1e999"),
            ("nan", b"NaN"),
            ("deep", b"[" * 100_000),
            ("deep-closed", b"[" * 20_000 + b"]" * 20_000),
            ("deep-object", b'{"a":' * 20_000 + b"1" + b"}" * 20_000),
            ("binary", bytes(range(256))),
            ("bad-utf8", b'{"s3": "\xff\xfe"}'),
            ("bom", b"\xef\xbb\xbf{}"),
            ("string", b'"x"'),
        ):
            # a UTF-8 byte order mark may be skipped (RFC 8259): "{}" after it is a valid /simulate (every field defaulted)
            out.append(
                Case(
                    f"raw:{path}:{name}",
                    "POST",
                    path,
                    body,
                    headers=json_ct,
                    must_refuse=not (name == "bom" and path == "/simulate"),
                )
            )
        over = b'{"x": "' + b"a" * (MAX_BODY + 10) + b'"}'
        if path != "/invariants":
            out.append(Case(f"raw:{path}:oversized", "POST", path, over, headers=json_ct, must_refuse=True, expect=413))
        out.append(
            Case(
                f"raw:{path}:text-plain",
                "POST",
                path,
                b"s3=2",
                headers={"content-type": "text/plain"},
                must_refuse=True,
            )
        )
    # duplicate keys: the last one counts (as every JSON parser the service uses); a hostile last value must be refused
    spins = {"body": BODY, "s3": 2.0, "p_theta": 0.5, "grid": 8}
    base = _encode(spins)[:-1]
    for key, value in (("s3", b"1e308"), ("grid", b"100000"), ("p_theta", b"NaN"), ("body", b"null")):
        out.append(
            Case(
                f"dup:{key}",
                "POST",
                "/ellipses",
                base + b', "' + key.encode() + b'": ' + value + b"}",
                headers=json_ct,
                must_refuse=True,
                sent_field=key,
            )
        )
    out.append(
        Case(
            "dup:kind",
            "POST",
            "/jobs",
            b'{"kind": "evaluate", "params": {"episodes": 1}, "kind": "nope"}',
            headers=json_ct,
            must_refuse=True,
            sent_field="kind",
        )
    )
    # query strings and path parameters
    for value in ("0", "-1", "101", "1e2", "2.5", "nan", "inf", "", "9" * 400, "é", "1 OR 1=1", "true"):
        out.append(
            Case(
                f"query:limit={_short(value)}",
                "GET",
                "/jobs",
                params={"limit": value},
                must_refuse=not (value.isdigit() and 1 <= int(value) <= 100),
                sent_field="limit",
            )
        )
    for value in (
        "nonsense",
        "1:zz",
        "1e999:ab",
        "nan:ab",
        "-1:ab",
        "1.5:" + "a" * 65,
        "' OR 1=1 --",
        "x" * 101,
        "é:ab",
        "",
    ):
        out.append(
            Case(
                f"query:before={_short(value)}",
                "GET",
                "/jobs",
                params={"before": value},
                must_refuse=bool(value),
                sent_field="before",
            )
        )
    for job_id in ("0" * 32, "..%2F..%2Fjobs.sqlite3", "x" * 65, "%00", "%C3%A9", "a" * 64, "' OR 1=1 --", "%2e%2e"):
        for method, suffix in (("GET", ""), ("DELETE", ""), ("GET", "/artifact")):
            out.append(
                Case(
                    f"id:{method}:{suffix}:{_short(job_id)}",
                    method,
                    f"/jobs/{job_id}{suffix}",
                    must_refuse=True,
                    sent_field="job_id",
                )
            )
    out.append(
        Case(
            "artifact:name",
            "GET",
            "/jobs/" + "0" * 32 + "/artifact",
            params={"name": "../../jobs.sqlite3"},
            must_refuse=True,
            sent_field="job_id",
        )
    )
    # Host headers: only loopback names are answered (400 bad-host otherwise)
    for host in (
        "evil.example",
        "evil.example:8000",
        "localhost.evil.example",
        "127.0.0.1.nip.io",
        "127.0.0.2",
        "0.0.0.0",
        "[::2]:80",
        "[::1",
        "x" * 4000,
        "localhost@evil.example",
        "",
        "10.0.0.1:8000",
        "127.0.0.1:80:80",
        "é.example",
    ):
        out.append(
            Case(
                f"host:{_short(host)}",
                "GET",
                "/health",
                headers={"host": host},
                must_refuse=True,
                expect=400,
                sent_field="host",
            )
        )
    for host in ("LOCALHOST", "127.0.0.1:1", "[::1]:65535", "localhost:0"):
        out.append(Case(f"host-ok:{host}", "GET", "/health", headers={"host": host}))
    # methods a path does not have: 405 with Allow
    for path in (
        "/health",
        "/limits",
        "/scenes",
        "/methods",
        "/ellipses",
        "/simulate",
        "/invariants",
        "/jobs",
        "/jobs/" + "0" * 32,
        "/jobs/" + "0" * 32 + "/artifact",
    ):
        for method in ("PUT", "PATCH", "OPTIONS", "TRACE", "FOO"):
            out.append(Case(f"method:{method}:{path}", method, path, must_refuse=True, expect=405, sent_field="method"))
        if path in ("/health", "/limits", "/scenes", "/methods"):
            out.append(
                Case(
                    f"method:POST:{path}",
                    "POST",
                    path,
                    b"{}",
                    headers=json_ct,
                    must_refuse=True,
                    expect=405,
                    sent_field="method",
                )
            )
    return out


# -- judging ------------------------------------------------------------------------------------------------
RELATED = ({"from", "to"}, {"t", "state", "energy", "casimir", "p_theta", "rotation", "initial_state", "meta"})
"""Fields refused together: a family's from < to; a trajectory's arrays as long as its ``t``."""


def _related(sent: str | None, named: str) -> bool:
    """Whether the error's field ``named`` is the field the hostile value went to, a part or a parent of it, or a field
    it is checked against (:data:`RELATED`). ``POST /invariants`` names a trajectory's fields ``trajectory.…``, as
    ``flatbody invariants`` does."""
    if (
        sent is None or named in ("body", "request") or (sent == "job_id" and named == "path")
    ):  # an id with a "/" is no route
        return True
    named = named.removeprefix("trajectory.")
    a, b = sent.split("."), named.split(".")
    n = min(len(a), len(b))
    if a[:n] == b[:n] or (a[0] == "params" and named in ("params", "kind")):
        return True
    a, b = [x for x in a if x != "params"], [x for x in b if x != "params"]
    return bool(a and b) and any(a[0] in group and b[0] in group for group in RELATED)


def judge(case: Case, status: int | None, headers: dict[str, str] | None, text: str) -> list[str]:
    """What is wrong with the answer (``status`` None: no answer within the timeout): a list of problem names."""
    if status is None:
        return ["hang"]
    problems = []
    if status >= 500 and not (status == 503 and '"unavailable"' in text):
        problems.append("5xx")
    if 200 <= status < 300 and case.must_refuse:
        problems.append("silent-accept")
    if case.expect is not None and status != case.expect:
        problems.append(f"status-{status}-not-{case.expect}")
    if 400 <= status < 500:
        try:
            data = json.loads(text)
        except ValueError:
            return problems + ["unnamed"]
        if not isinstance(data, dict) or "\n" in str(data.get("detail", "\n")):
            return problems + ["unnamed"]
        named = data.get("field")
        if status == 405:
            if not (headers or {}).get("allow"):
                problems.append("405-without-allow")
        elif data.get("kind") == "integration":
            if data.get("why") is None:
                problems.append("unnamed")
        elif not named:
            problems.append("unnamed")
        elif not _related(case.sent_field, named):
            problems.append("misnamed")
    return problems


# -- running ------------------------------------------------------------------------------------------------
def start_service(
    data_dir: Path, log_path: Path, *, workers: int = 1, env: dict[str, str] | None = None, timeout: float = 90.0
):
    """``flatbody serve`` on a free loopback port with the corpus' small limits and its log in ``log_path``:
    ``(process, url)`` once /health answers (:func:`flatbody_env.service.launch.start_service`)."""
    from flatbody_env.service.launch import start_service as start

    return start(data_dir, workers=workers, timeout=timeout, env={**SMALL_LIMITS, **(env or {})}, log_path=log_path)


def send(http, case: Case, timeout: float):
    """Send one case: ``(status, headers, text)``, status None when it did not answer within ``timeout``."""
    import httpx

    headers = {k: v.encode("utf-8") for k, v in case.headers.items()}  # bytes: a non-ASCII Host is sent as is
    try:
        r = http.request(
            case.method, case.path, content=case.body, params=case.params, headers=headers, timeout=timeout
        )
    except httpx.TimeoutException:
        return None, None, ""
    if 200 <= r.status_code < 300 and case.method == "POST" and case.path == "/jobs":
        http.delete(f"/jobs/{r.json()['id']}", timeout=timeout)  # the job endpoints are fuzzed, not the work
    return r.status_code, dict(r.headers), r.text


@dataclass
class Tally:
    cases: int = 0
    statuses: Counter = field(default_factory=Counter)
    problems: Counter = field(default_factory=Counter)
    examples: dict[str, list[str]] = field(default_factory=dict)
    seconds: float = 0.0
    tracebacks: int = 0

    def add(self, case: Case, status, problems: list[str], text: str) -> None:
        self.cases += 1
        self.statuses[status] += 1
        for p in problems:
            self.problems[p] += 1
            self.examples.setdefault(p, [])
            if len(self.examples[p]) < 12:
                self.examples[p].append(f"{case.name} -> {status} {text[:160]}")

    def counts(self) -> dict[str, int]:
        return {
            "cases": self.cases,
            "tracebacks": self.tracebacks,
            "hangs": self.problems["hang"],
            "silent_accepts": self.problems["silent-accept"],
            "5xx": self.problems["5xx"],
            "unnamed_4xx": self.problems["unnamed"] + self.problems["misnamed"] + self.problems["405-without-allow"],
            "wrong_status": sum(v for k, v in self.problems.items() if k.startswith("status-")),
        }

    def report(self) -> str:
        lines = [
            f"HTTP fuzz corpus: {self.cases} cases in {self.seconds:.1f} s; "
            + ", ".join(f"{k} {v}" for k, v in self.counts().items()),
            "statuses: " + ", ".join(f"{k}: {v}" for k, v in sorted(self.statuses.items(), key=lambda kv: str(kv[0]))),
        ]
        for name, examples in self.examples.items():
            lines += [f"  {name}:"] + [f"    {e}" for e in examples]
        return "\n".join(lines)


def run(url: str, cases: list[Case], *, timeout: float = 30.0) -> Tally:
    import httpx

    tally = Tally()
    t0 = time.monotonic()
    with httpx.Client(base_url=url) as http:
        for case in cases:
            status, headers, text = send(http, case, timeout)
            tally.add(case, status, judge(case, status, headers, text), text)
    tally.seconds = time.monotonic() - t0
    return tally


def base_trajectory(url: str) -> dict:
    """A small trajectory (with R) from the service itself: the base body of ``POST /invariants``."""
    import httpx

    r = httpx.post(
        url + "/simulate", json={"scene": "default", "t_end": 0.2, "samples": 3, "with_rotation": True}, timeout=60
    )
    r.raise_for_status()
    return r.json()


def count_tracebacks(log_path: Path) -> int:
    return log_path.read_text(encoding="utf-8", errors="replace").count("Traceback")


if (
    __name__ == "__main__"
):  # python tests/fuzz/http_corpus.py [URL]: the corpus against a running service, or one started here
    import tempfile

    if len(sys.argv) > 1:
        target = sys.argv[1]
        tally = run(target, fixed_cases(base_trajectory(target)))
    else:
        folder = Path(tempfile.mkdtemp(prefix="flatbody-http-fuzz-"))
        proc, target = start_service(folder / "data", folder / "serve.log")
        try:
            tally = run(target, fixed_cases(base_trajectory(target)))
        finally:
            stop_service(proc)
        tally.tracebacks = count_tracebacks(folder / "serve.log")
    print(tally.report())
    sys.exit(0 if not any(v for k, v in tally.counts().items() if k != "cases") else 1)
