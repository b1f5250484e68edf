"""The FastAPI application: routers, one error shape, the guards at the edge (Host, bearer token, body
size and pace), lifespan."""

from __future__ import annotations

import asyncio
import fcntl
import hmac
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import IO, Any

from fastapi import FastAPI
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

import service
from service.jobs import JobManager, SceneCache
from service.storage import Storage

from .config import Settings, host_name
from .deps import AppState, StoreCache
from .errors import common_error_responses, error_response, install_error_handlers
from .routes import health, jobs, render, scenes, stores

log = logging.getLogger("render_budget.api")

PUBLIC_PATHS = frozenset({"/health"})


def _header(scope: Scope, name: bytes) -> bytes | None:
    for key, value in scope["headers"]:
        if key == name:
            return bytes(value)
    return None


class HostGuard:
    """Answer only requests addressed to an allowed host name (any port). A loopback service without a
    token is otherwise reachable from any web page through DNS rebinding: the page's own name, made to
    resolve to 127.0.0.1, arrives in the Host header."""

    def __init__(self, app: ASGIApp, allowed: frozenset[str]) -> None:
        self.app = app
        self.allowed = allowed

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        raw = _header(scope, b"host")
        name = host_name(raw.decode("latin-1")) if raw else ""
        if name in self.allowed:
            await self.app(scope, receive, send)
            return
        shown = repr(name[:64]) if name else "missing"
        message = (f"Host header {shown} is not allowed: this service answers to "
                   f"{', '.join(sorted(self.allowed))} (configure RENDER_BUDGET_ALLOWED_HOSTS)")
        response = error_response(400, message, code="host_not_allowed", headers={"Connection": "close"})
        await response(scope, receive, send)


class BearerTokenGuard:
    """Every route but /health (docs and OpenAPI included) needs ``Authorization: Bearer <token>``."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app = app
        self._token = token.encode()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["path"] in PUBLIC_PATHS:
            await self.app(scope, receive, send)
            return
        auth = _header(scope, b"authorization") or b""
        scheme, _, given = auth.partition(b" ")
        if scheme.lower() == b"bearer" and hmac.compare_digest(given.strip(), self._token):
            await self.app(scope, receive, send)
            return
        message = "missing bearer token" if not auth else "invalid bearer token"
        response = error_response(401, message, headers={"WWW-Authenticate": "Bearer"})
        await response(scope, receive, send)


class BodyTooLarge(StarletteHTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body exceeds the limit of {limit} bytes",
                         headers={"Connection": "close"})


class BodyTimeout(StarletteHTTPException):
    def __init__(self, seconds: float) -> None:
        super().__init__(408, f"request body stalled: nothing arrived for {seconds:g} s",
                         headers={"Connection": "close"})


class BodyGuard:
    """Bodies are limited in size (refused before reading when Content-Length says so, cut off as soon
    as they pass the limit) and in pace (a body that stops arriving for ``timeout_s`` is cut off, so a
    stalled client holds neither a connection nor a temporary file). Uploads have their own limit."""

    def __init__(self, app: ASGIApp, *, default_limit: int, upload_limit: int, timeout_s: float) -> None:
        self.app = app
        self.default_limit = default_limit
        self.upload_limit = upload_limit
        self.timeout_s = timeout_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        upload = scope["method"] == "POST" and scope["path"].rstrip("/") == "/scenes"
        limit = self.upload_limit if upload else self.default_limit
        length = _header(scope, b"content-length")
        if length is not None:
            try:
                declared = int(length)
            except ValueError:
                await error_response(400, "invalid Content-Length header")(scope, receive, send)
                return
            if declared > limit:
                await error_response(413, f"request body of {declared} bytes exceeds the limit of {limit} "
                                          "bytes", headers={"Connection": "close"})(scope, receive, send)
                return
        has_body = (length is not None and length != b"0") or _header(scope, b"transfer-encoding") is not None
        received = 0
        body_done = not has_body

        async def guarded() -> Message:
            nonlocal received, body_done
            if body_done:
                return await receive()
            try:
                async with asyncio.timeout(self.timeout_s):
                    message = await receive()
            except TimeoutError:
                raise BodyTimeout(self.timeout_s) from None
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise BodyTooLarge(limit)
                body_done = not message.get("more_body", False)
            return message

        started = False

        async def tracked(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, guarded, tracked)
        except (BodyTooLarge, BodyTimeout) as exc:  # raised where no exception handler was in between
            if started:
                raise
            await error_response(exc.status_code, exc.detail, headers=exc.headers)(scope, receive, send)


def lock_data_dir(data_dir: Path) -> IO[bytes]:
    """One service per data directory: two would both resume the same jobs. The advisory lock dies with
    the process, so a restart after a crash is never blocked."""
    data_dir.mkdir(parents=True, exist_ok=True)
    handle = open(data_dir / "service.lock", "ab")  # held for the app's lifetime
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        handle.close()
        raise RuntimeError(f"data directory {data_dir} is in use by another render-budget service") from exc
    return handle


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app; storage and the job runner start in its lifespan (so tests can run several)."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        lock = lock_data_dir(settings.data_dir)
        storage = Storage(settings.data_dir)
        scene_cache = SceneCache(storage, capacity=settings.scene_cache_size)
        manager = JobManager(storage, scene_cache, workers=settings.job_workers,
                             dask_scheduler=settings.dask_scheduler, render_threads=settings.render_threads,
                             eval_workers=settings.eval_workers, ship_scenes=settings.dask_ship_scenes,
                             eval_cache_max_bytes=settings.eval_cache_max_bytes)
        app.state.render_budget = AppState(settings=settings, storage=storage, scenes=scene_cache,
                                           jobs=manager, stores=StoreCache(storage,
                                                                           capacity=settings.store_cache_size))
        manager.start()
        log.info("render-budget service: data in %s, executor %s", storage.data_dir,
                 manager.executor_description)
        try:
            yield
        finally:
            manager.stop()
            storage.close()
            lock.close()  # releases the lock (the OS does the same if the process dies)

    app = FastAPI(
        title="render-budget",
        version=service.__version__,
        summary="Power-optimal ray-tracing settings along camera paths",
        description="Upload a scene, optimise a camera path in the background, query the Pareto store.",
        lifespan=lifespan,
        telemetry={"tracing": False, "metrics": False, "logs": False, "operation_spans": False},
    )
    install_error_handlers(app)
    for module in (stores, health, scenes, jobs, render):  # stores first: its query is the hot path
        app.include_router(module.router, responses=common_error_responses(
            token=settings.token is not None and module is not health))
    _refine_openapi(app, bearer=settings.token is not None)
    app.add_middleware(BodyGuard, default_limit=settings.max_body_bytes,
                       upload_limit=settings.max_upload_bytes, timeout_s=settings.body_read_timeout_s)
    if settings.token is not None:
        app.add_middleware(BearerTokenGuard, token=settings.token.get_secret_value())
    allowed = settings.host_allow_list()
    if allowed is not None:
        app.add_middleware(HostGuard, allowed=allowed)  # outermost: refused before anything else runs
    return app


def _refine_openapi(app: FastAPI, *, bearer: bool) -> None:
    """The OpenAPI document as the service answers: FastAPI's generic 422 body becomes the one error
    shape every failure has, every error is JSON whatever the route streams, and with a token the bearer
    scheme every route but /health needs."""
    plain = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = plain()
            error_ref = {"$ref": "#/components/schemas/ErrorResponse"}
            for path, operations in schema["paths"].items():
                for operation in operations.values():
                    if "HTTPValidationError" in str(operation["responses"].get("422")):
                        operation["responses"]["422"] = {
                            "description": "invalid request: the details name the fields",
                            "content": {"application/json": {"schema": error_ref}}}
                    for status, answer in operation["responses"].items():
                        stream = answer.get("content", {}).get("text/event-stream", {})
                        if "itemSchema" in stream:  # events are described one by one, not as a string
                            stream.pop("schema", None)
                        if status.startswith(("4", "5")) and "ErrorResponse" in str(answer.get("content")):
                            answer["content"] = {"application/json": {"schema": error_ref}}  # errors are JSON
                            # (FastAPI files them under the route's own media type, e.g. text/event-stream)
                    if bearer:
                        operation["security"] = [] if path in PUBLIC_PATHS else [{"bearer": []}]
            components = schema.setdefault("components", {})
            for generic_name in ("HTTPValidationError", "ValidationError"):
                components.get("schemas", {}).pop(generic_name, None)
            if bearer:
                components["securitySchemes"] = {"bearer": {"type": "http", "scheme": "bearer"}}
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
