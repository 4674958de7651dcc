"""The ASGI application of the analysis service (FastAPI): endpoints, errors, limits, the page.

:func:`create_app` builds the app; ``flatbody serve`` runs it with uvicorn. The request-path
computations (``/ellipses``, ``/stability``, ``/simulate``, ``/invariants``, ``/scenes``,
``/methods``) run in a pool of worker processes, so the event loop only waits: a slow request never
blocks ``/health``. Long work goes through ``/jobs`` (:mod:`flatbody_env.service.jobs`).

Errors are :class:`~flatbody_env.service.models.ErrorAnswer` objects, one line naming the field
and the allowed range or the limit: 422 for bad input and failed integrations (with the
``IntegrationError``'s time and reason), 413 for bodies or work over the limits, 404 for unknown
jobs, 409 for an artifact of an unfinished job, 429 (with ``Retry-After``) when the job queue is
full, 503 for the server's own faults (the workers restarting, the job database missing or corrupt,
the disk full), never a 422: bad input is the client's fault, those are not.

Quotas keep one client from holding the service: jobs queued in all and per client address,
every stored string and array bounded by the request models, ``GET /jobs`` in pages of bounded
size without results. Heavy answers are rendered off the event loop (JSON bytes built in the
worker process or a thread, a job's stored result spliced in unparsed), and the large body of
``POST /invariants`` is parsed in a worker process, so ``/health`` stays answered. Requests must
name an allowed ``Host`` (loopback names by default: a defence against DNS rebinding).

``/docs`` (Swagger UI) and ``/redoc`` load their scripts from the service itself (:data:`DOCS_ASSETS`),
so they work on a network without internet access, as the page does.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import sqlite3
import sys
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Path as PathParam, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Route

from flatbody_env.service import models
from flatbody_env.service.jobs import JobRunner, die_with_service, download_name, process_context
from flatbody_env.service.limits import DEFAULT_LIMITS, Limits
from flatbody_env.service.store import JobStore, QueueFull

PAGE_DIR = Path(__file__).with_name("page")
PALETTE_MARK = "<!-- palette -->"
"""Where :func:`page_html` puts the colours into ``index.html``."""


def palette_css() -> str:
    """The page's colours as CSS custom properties ``--color-NAME: #rrggbb`` on ``:root``, from
    :data:`flatbody_env.env.rendering.COLORS` — the palette of the recordings and the ``rgb_array``
    frames, so that λ, μ, ϱ, s₃, H … have one colour on the page, in the viewer and in the frames.
    ``page.css`` and ``page.js`` read these properties and name no colour of a variable themselves."""
    from flatbody_env.env.rendering import COLORS

    names = "".join(f" --color-{name}: #{r:02x}{g:02x}{b:02x};" for name, (r, g, b) in COLORS.items())
    return f'<style id="palette">:root {{{names} }}</style>'


def page_html() -> str:
    """The page (``page/index.html``) with :func:`palette_css` in its head."""
    return (PAGE_DIR / "index.html").read_text(encoding="utf-8").replace(PALETTE_MARK, palette_css(), 1)


DOCS_ASSETS = "/docs-assets"
"""Where the service serves Swagger UI's and ReDoc's scripts for ``/docs`` and ``/redoc`` (fastapi-offline)."""

_ERRORS = {
    400: {"model": models.ErrorAnswer, "description": "a Host header the service does not answer to"},
    413: {"model": models.ErrorAnswer, "description": "the body or the work is over a limit (the detail names it)"},
    422: {
        "model": models.ErrorAnswer,
        "description": "bad input (the field and its allowed range) or a failed integration",
    },
    503: {
        "model": models.ErrorAnswer,
        "description": "a server fault: the workers are restarting, the job database is missing or "
        "corrupt, or the disk is full (one line); try again later",
    },
}
_JOB_ERRORS = {
    400: _ERRORS[400],
    404: {"model": models.ErrorAnswer, "description": "no such job"},
    422: _ERRORS[422],
    503: _ERRORS[503],
}
_QUEUE_FULL = {
    429: {
        "model": models.ErrorAnswer,
        "description": "the job queue is full (in all or for this client): try again after Retry-After seconds",
        "headers": {"Retry-After": {"description": "seconds to wait", "schema": {"type": "integer"}}},
    }
}

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
"""The ``Host`` names the service answers to by default (``FLATBODY_ALLOWED_HOSTS`` changes them)."""


def _finite_json(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_json(v) for v in value]
    return value


class AnswerResponse(JSONResponse):
    """JSON as the ``flatbody`` command prints it (``json.dumps``), with NaN/inf (never valid JSON) as null."""

    def render(self, content: Any) -> bytes:
        try:
            text = json.dumps(content, allow_nan=False)
        except ValueError:
            text = json.dumps(_finite_json(content), allow_nan=False)
        return text.encode("utf-8")


def error(status: int, kind: str, detail: str, **extra: Any) -> AnswerResponse:
    """An :class:`~flatbody_env.service.models.ErrorAnswer` response."""
    body = {"detail": detail, "kind": kind, **{k: v for k, v in extra.items() if v is not None}}
    return AnswerResponse(body, status_code=status)


def _error_from(data: dict[str, Any]) -> AnswerResponse:
    data = dict(data)
    status = data.pop("status", None) or (413 if data["kind"] == "too-large" else 422)
    return error(status, data.pop("kind"), data.pop("detail"), **data)


class ServerFault(Exception):
    """The service's own fault (the job database or the disk): answered 503, one line."""


async def _store(call, *args, **kwargs):
    """``call(*args)`` in a thread; a database or disk failure becomes :class:`ServerFault`."""
    try:
        return await asyncio.to_thread(call, *args, **kwargs)
    except (sqlite3.Error, OSError) as exc:
        raise ServerFault(_fault_text(exc)) from None


def _fault_text(exc: BaseException) -> str:
    text = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
    return f"the service cannot use its job database or disk ({type(exc).__name__}: {text}); try again later"


class HostCheck:
    """ASGI middleware: answer only requests whose ``Host`` is one of ``allowed`` (``*`` allows any);
    others get 400 (``bad-host``), as starlette's ``TrustedHostMiddleware``, with IPv6 literals and the
    service's one-line error."""

    def __init__(self, app, allowed: tuple[str, ...]) -> None:
        self.app = app
        self.allowed = {h.lower().strip("[]") for h in allowed}

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] not in ("http", "websocket") or "*" in self.allowed:
            return await self.app(scope, receive, send)
        host = ""
        for name, value in scope.get("headers", ()):
            if name == b"host":
                host = value.decode("latin-1").strip().lower()
                break
        name = (
            host[1 : host.index("]")]
            if host.startswith("[") and "]" in host
            else host.rsplit(":", 1)[0]
            if host.count(":") == 1
            else host
        )
        if name in self.allowed:
            return await self.app(scope, receive, send)
        response = error(
            400,
            "bad-host",
            f"host: this service does not answer to the Host {host[:60]!r} (allowed: "
            f"{', '.join(sorted(self.allowed))}; set FLATBODY_ALLOWED_HOSTS)",
            field="host",
        )
        await response(scope, receive, send)


class BodyLimit:
    """ASGI middleware: request bodies over ``max_bytes`` get 413 before the app reads them."""

    def __init__(self, app, max_bytes: int, larger: dict[str, int] | None = None) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.larger = dict(larger or {})

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        limit = self.larger.get(scope.get("path", ""), self.max_bytes)
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                try:
                    size = int(value)
                except ValueError:
                    size = -1
                if size > limit or size < 0:
                    return await self._refuse(scope, receive, send, limit)
        chunks: list[bytes] = []
        total = 0
        more = True
        while more:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            total += len(chunk)
            if total > limit:
                return await self._refuse(scope, receive, send, limit)
            chunks.append(chunk)
            more = message.get("more_body", False)
        body = b"".join(chunks)
        sent = False

        async def replay():
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    async def _refuse(self, scope, receive, send, limit: int) -> None:
        response = error(413, "too-large", f"body: the request body may hold at most {limit} bytes", field="body")
        await response(scope, receive, send)


class Service:
    """The app's state: the job store and runner, and the pool of request workers."""

    def __init__(self, data_dir: str | Path, workers: int, limits: Limits) -> None:
        try:
            self.store = JobStore(data_dir)
        except sqlite3.Error as exc:
            raise ValueError(
                f"data-dir: the job database {Path(data_dir) / 'jobs.sqlite3'} cannot be used ({exc}); "
                "move it away to start with an empty one"
            ) from None
        self.store.lock()
        self.runner = JobRunner(self.store, workers)
        self.workers = workers
        self.limits = limits
        self.pool: ProcessPoolExecutor | None = None
        self.interrupted = 0

    def start(self) -> None:
        self.interrupted = self.runner.start()
        self._new_pool()

    def _new_pool(self) -> None:
        from flatbody_env.service.answers import warm_up

        self.pool = ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=process_context(),
            initializer=die_with_service,
            initargs=(os.getpid(),),
        )
        for _ in range(self.workers):
            self.pool.submit(warm_up)

    def stop(self) -> None:
        self.runner.stop()
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)  # waits for a running request (bounded by the limits)
        self.store.unlock()

    async def answer(self, name: str, payload: Any) -> Response:
        """Compute ``answers.ANSWERS[name](payload)`` in a worker process, which also renders the answer's JSON
        (so the event loop only passes bytes on); the answer or the error response."""
        from flatbody_env.service.answers import outcome_json

        try:
            future = self.pool.submit(outcome_json, name, payload)
        except BrokenProcessPool:
            self._new_pool()
            return error(503, "unavailable", "the worker processes are restarting; try again")
        try:
            ok, data = await asyncio.wait_for(asyncio.wrap_future(future), timeout=self.limits.request_seconds)
        except TimeoutError:
            return error(
                413,
                "too-large",
                f"request: took longer than {self.limits.request_seconds:g} s; send it as a job (POST /jobs)",
                field="request",
            )
        except BrokenProcessPool:
            self._new_pool()
            return error(503, "unavailable", "a worker process died while answering (out of memory?); try again")
        if ok:
            return Response(data, media_type="application/json")
        return _error_from(data)


def create_app(
    data_dir: str | Path = "flatbody-data",
    *,
    workers: int = 2,
    limits: Limits | None = None,
    allowed_hosts: tuple[str, ...] | None = None,
) -> FastAPI:
    """The analysis service.

    Parameters
    ----------
    data_dir : str or Path
        Where the job database (``jobs.sqlite3``) and the jobs' files live.
    workers : int
        Worker processes for requests, and jobs run at once.
    limits : Limits, optional
        The bounds on bodies, work and quotas (default :data:`~flatbody_env.service.limits.DEFAULT_LIMITS`),
        with any ``FLATBODY_LIMIT_<NAME>`` environment variable applied.
    allowed_hosts : tuple of str, optional
        The ``Host`` names answered (default: ``FLATBODY_ALLOWED_HOSTS``, comma-separated, else
        :data:`LOOPBACK_HOSTS`; ``*`` answers any).
    """
    from flatbody_env import __version__
    from flatbody_env.physics import validation

    workers = validation.workers("workers", workers)
    limits = (limits or DEFAULT_LIMITS).with_environment()
    if allowed_hosts is None:
        env_hosts = os.environ.get("FLATBODY_ALLOWED_HOSTS", "")
        allowed_hosts = tuple(h.strip() for h in env_hosts.split(",") if h.strip()) or LOOPBACK_HOSTS
    service = Service(data_dir, workers, limits)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        service.start()
        if service.interrupted:
            sys.stderr.write(
                f"flatbody serve: {service.interrupted} job(s) were running when the service stopped; marked failed\n"
            )
        try:
            yield
        finally:
            service.stop()

    app = FastAPIOffline(  # FastAPI with /docs (Swagger UI) and /redoc whose scripts the service serves itself
        static_url=DOCS_ASSETS,
        title="flatbody analysis service",
        version=__version__,
        description="Stationary ellipses, stability, families, simulations and rerun recordings of a flat affinely-rigid body "
        "with thickness. Answers are the `flatbody` command's JSON answers.",
        lifespan=lifespan,
    )
    app.state.service = service
    app.add_middleware(
        BodyLimit, max_bytes=limits.max_body_bytes, larger={"/invariants": limits.max_trajectory_body_bytes}
    )
    app.add_middleware(HostCheck, allowed=tuple(allowed_hosts))
    # ReDoc's bundle shows a logo it fetches from cdn.redoc.ly: served here with that address emptied
    # (the image fails to load and ReDoc leaves it out), so /redoc makes no request outside the service.
    # Inserted ahead of the /docs-assets mount, which would otherwise answer this path.
    app.router.routes.insert(
        0, Route(f"{DOCS_ASSETS}/redoc.standalone.js", _redoc_bundle, methods=["GET"], include_in_schema=False)
    )

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        where = {"/simulate": "request", "/jobs": "job"}.get(request.url.path, "other")
        return _error_from(models.describe_errors(list(exc.errors()), where=where))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        if exc.status_code == 400:  # a body that cannot be decoded (FastAPI says 400): bad input, as every other
            return error(422, "validation", f"body: not valid JSON ({exc.detail})", field="body")
        kind = {404: "not-found", 405: "method-not-allowed", 409: "conflict", 413: "too-large"}.get(
            exc.status_code, "validation"
        )
        named = {404: "path", 405: "method"}.get(exc.status_code)  # no such path / a method the path does not have
        detail = str(exc.detail)
        if exc.status_code == 404:
            detail = f"path: no such endpoint {request.url.path[:80]!r} (see /docs)"
        elif exc.status_code == 405:
            detail = f"method: {request.method[:20]} is not allowed on {request.url.path[:80]}"
        response = error(exc.status_code, kind, detail, field=named)
        for name, value in (exc.headers or {}).items():
            response.headers[name] = value
        if (
            exc.status_code == 405
        ):  # Allow: every method of every route at this path (starlette names the first route's only)
            allowed = set()
            for route in app.routes:
                methods = getattr(route, "methods", None)
                regex = getattr(route, "path_regex", None)
                if methods and regex is not None and regex.match(request.url.path):
                    allowed |= set(methods)
            if allowed:
                response.headers["Allow"] = ", ".join(sorted(allowed))
        return response

    @app.exception_handler(ServerFault)
    async def _fault(request: Request, exc: ServerFault):
        return error(503, "unavailable", str(exc))

    @app.exception_handler(QueueFull)
    async def _full(request: Request, exc: QueueFull):
        response = error(429, "too-many-jobs", str(exc), field="jobs")
        response.headers["Retry-After"] = str(int(limits.retry_after_s))
        return response

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):  # pragma: no cover - a last line, never a traceback
        if isinstance(exc, (sqlite3.Error, OSError)):  # the server's own fault, not the request's
            return error(503, "unavailable", _fault_text(exc))
        return error(503, "unavailable", f"the service failed to answer ({type(exc).__name__}); try again later")

    # -- plain answers ---------------------------------------------------------------------------
    @app.get("/health", response_model=models.Health, tags=["service"])
    async def health() -> dict[str, str]:
        """Liveness: always answered by the event loop, never behind a computation."""
        return {"status": "ok", "version": __version__}

    @app.get("/limits", tags=["service"], response_model=dict[str, float])
    async def get_limits() -> dict[str, float]:
        """The bounds this service runs with (requests over them get 413)."""
        return limits.as_dict()

    @app.get("/scenes", tags=["physics"], response_model=dict[str, dict[str, Any]], responses=_ERRORS)
    async def scenes():
        """The built-in scenes: the ``flatbody scenes --json`` answer."""
        return await service.answer("scenes", {})

    @app.get("/methods", tags=["physics"], response_model=list[models.MethodAnswer], responses=_ERRORS)
    async def methods():
        """The integrators: the ``flatbody methods --json`` answer."""
        return await service.answer("methods", {})

    @app.post("/ellipses", tags=["analysis"], response_model=models.EllipsesAnswer, responses=_ERRORS)
    async def ellipses(request: models.SpinsRequest):
        """Stationary ellipses for given s3, p_theta (eqs. 52-54 of the paper): ``flatbody ellipses --json``."""
        return await service.answer("ellipses", request.model_dump(by_alias=True))

    @app.post("/stability", tags=["analysis"], response_model=models.StabilityAnswer, responses=_ERRORS)
    async def stability(request: models.SpinsRequest):
        """Eigenvalues and classification of each stationary ellipse: ``flatbody stability --json``."""
        return await service.answer("stability", request.model_dump(by_alias=True))

    @app.post("/simulate", tags=["physics"], response_model=models.TrajectoryAnswer, responses=_ERRORS)
    async def simulate(request: models.SimulateRequest):
        """Integrate a scene: the ``flatbody simulate`` JSON. Integration failures are 422 with ``when`` and ``why``."""
        return await service.answer("simulate", request.model_dump(by_alias=True))

    @app.post(
        "/invariants",
        tags=["analysis"],
        response_model=models.InvariantsAnswer,
        responses=_ERRORS,
        openapi_extra={
            "requestBody": {
                "required": True,
                "content": {"application/json": {"schema": {"$ref": "#/components/schemas/TrajectoryRequest"}}},
            }
        },
    )
    async def invariants(request: Request):
        """Invariants and drift table along a trajectory (the ``flatbody simulate`` JSON): ``flatbody invariants --json``.

        The body (up to ``max_trajectory_body_bytes``) is read and checked in a worker process, not in the event loop."""
        return await service.answer("invariants-json", await request.body())

    # -- jobs --------------------------------------------------------------------------------------
    @app.post("/jobs", tags=["jobs"], status_code=202, response_model=models.JobCreated, responses=_ERRORS)
    async def create_job(http: Request, request: models.JobRequest):
        """Queue a job (simulate, family, stability-map, record, evaluate); it runs in a worker process.

        At most ``max_queued_jobs`` jobs wait at once, ``max_queued_per_client`` of them from one client address,
        and ``max_stored_jobs`` are kept: past them the answer is 429 with ``Retry-After``."""
        job = {"kind": request.kind, "params": request.params.model_dump(by_alias=True)}
        checked = await service.answer("check-job", job)
        if checked.status_code != 200:
            return checked
        client = http.client.host if http.client else None
        job_id = await _store(
            service.runner.submit,
            job["kind"],
            job["params"],
            client=client,
            max_queued=limits.max_queued_jobs,
            max_queued_per_client=limits.max_queued_per_client,
            max_stored=limits.max_stored_jobs,
        )
        return AnswerResponse({"id": job_id}, status_code=202)

    @app.get(
        "/jobs",
        tags=["jobs"],
        response_model=models.JobList,
        responses={400: _ERRORS[400], 422: _ERRORS[422], 503: _ERRORS[503]},
    )
    async def list_jobs(
        limit: int = Query(50, ge=1, le=limits.max_list_jobs),
        before: str | None = Query(
            None,
            max_length=100,
            pattern=r"^[0-9]{1,12}(\.[0-9]{1,20})?:[0-9a-f]{1,64}$",
            description="the `next` of the previous page",
        ),
    ):
        """A page of jobs, newest first, without their results (``GET /jobs/{id}`` has a job's result). A page holds
        at most ``limit`` jobs and ``max_list_bytes`` of JSON; ``next`` is the ``before`` of the next page."""
        body = await _store(service.store.list_json, limit, before=before, max_bytes=limits.max_list_bytes)
        return Response(body, media_type="application/json")

    @app.get("/jobs/{job_id}", tags=["jobs"], response_model=models.JobStatus, responses=_JOB_ERRORS)
    async def get_job(job_id: str = PathParam(max_length=64)):
        """A job's status, progress, result (when done) or error (when failed)."""
        body = await _store(service.store.get_json, job_id)
        if body is None:
            return error(404, "not-found", f"job_id: no job {job_id!r}", field="job_id")
        return Response(body, media_type="application/json")

    @app.get(
        "/jobs/{job_id}/artifact",
        tags=["jobs"],
        response_class=FileResponse,
        responses={
            **_JOB_ERRORS,
            409: {"model": models.ErrorAnswer, "description": "the job has not finished"},
            200: {
                "description": "the file (.rrd, .png, .csv, .json)",
                "content": {"application/octet-stream": {}, "image/png": {}, "text/csv": {}, "application/json": {}},
            },
        },
    )
    async def get_artifact(job_id: str = PathParam(max_length=64), name: str | None = Query(None, max_length=64)):
        """Stream a job's file: ``name`` one of the job's ``artifacts`` (default the first: .rrd, .png or .json), offered
        under a name that says what it holds (``flatbody-record-default-t5-1a2b3c4d.rrd``)."""
        job = await _store(service.store.get, job_id)
        if job is None:
            return error(404, "not-found", f"job_id: no job {job_id!r}", field="job_id")
        if job["status"] != "done":
            return error(
                409,
                "conflict",
                f"job_id: job {job_id} is {job['status']}; its files come when it is done",
                field="job_id",
            )
        names = job["artifacts"]
        chosen = names[0] if name is None and names else name
        if chosen not in names:
            refused = validation.refusal("name", f"be one of {', '.join(names) or '(none)'}", name)
            return error(404, "not-found", str(refused), field="name")
        path = service.store.job_dir(job_id) / chosen
        if not path.is_file():
            return error(404, "not-found", f"name: {chosen} is gone from the data dir", field="name")
        media = {".png": "image/png", ".csv": "text/csv", ".json": "application/json"}.get(
            path.suffix, "application/octet-stream"
        )
        return FileResponse(path, media_type=media, filename=download_name(job["kind"], job["params"], job_id, chosen))

    @app.delete("/jobs/{job_id}", tags=["jobs"], response_model=models.JobDeleted, responses=_JOB_ERRORS)
    async def delete_job(job_id: str = PathParam(max_length=64)):
        """Cancel a queued or running job (its process is stopped) and delete the job and its files."""
        job = await _store(service.store.get, job_id)
        if job is None:
            return error(404, "not-found", f"job_id: no job {job_id!r}", field="job_id")
        cancelled = await _store(service.runner.cancel, job_id)
        deleted = await _store(service.store.delete, job_id)
        return AnswerResponse({"id": job_id, "cancelled": cancelled, "deleted": deleted})

    # -- the page ----------------------------------------------------------------------------------
    @app.get("/", include_in_schema=False)
    async def page() -> Response:
        return HTMLResponse(page_html())

    @app.get("/favicon.ico", include_in_schema=False)
    async def favicon() -> Response:
        from flatbody_env.service.favicon import FAVICON_ICO

        return Response(FAVICON_ICO, media_type="image/x-icon", headers={"cache-control": "max-age=86400"})

    app.mount("/page", StaticFiles(directory=PAGE_DIR), name="page")

    def openapi() -> dict[
        str, Any
    ]:  # the trajectory body of /invariants is read by hand (in a worker): its schema added here
        if app.openapi_schema is None:
            from fastapi.openapi.utils import get_openapi
            from pydantic.json_schema import models_json_schema

            doc = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
            _, defs = models_json_schema(
                [(models.TrajectoryRequest, "validation")], ref_template="#/components/schemas/{model}"
            )
            schemas = doc.setdefault("components", {}).setdefault("schemas", {})
            for key, value in defs.get("$defs", {}).items():
                schemas.setdefault(key, value)
            app.openapi_schema = doc
        return app.openapi_schema

    app.openapi = openapi
    return app


REDOC_LOGO = "https://cdn.redoc.ly/redoc/logo-mini.svg"
"""The one outside address in ReDoc's bundle (its footer logo); :func:`_redoc_bundle` empties it."""


def _redoc_bundle(request: Request) -> Response:
    import fastapi_offline

    path = Path(fastapi_offline.__file__).with_name("static") / "redoc.standalone.js"
    text = path.read_text(encoding="utf-8").replace(REDOC_LOGO, "data:,")
    return Response(text, media_type="text/javascript; charset=utf-8", headers={"cache-control": "max-age=3600"})


def _public(job: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in job.items() if k not in ("pid", "client")}


def app_from_environment() -> FastAPI:
    """The app for ``uvicorn --factory flatbody_env.service.app:app_from_environment`` (``FLATBODY_DATA_DIR``,
    ``FLATBODY_WORKERS``)."""
    return create_app(
        os.environ.get("FLATBODY_DATA_DIR", "flatbody-data"), workers=int(os.environ.get("FLATBODY_WORKERS", "2"))
    )


__all__ = [
    "AnswerResponse",
    "BodyLimit",
    "HostCheck",
    "LOOPBACK_HOSTS",
    "PAGE_DIR",
    "PALETTE_MARK",
    "ServerFault",
    "Service",
    "app_from_environment",
    "create_app",
    "page_html",
    "palette_css",
]
