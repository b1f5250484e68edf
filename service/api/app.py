"""The FastAPI application: routers, one error shape, bearer-token and body-size guards, lifespan."""

from __future__ import annotations

import fcntl
import hmac
import logging
import re
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import IO

from fastapi import FastAPI
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

import service
from service.jobs import JobManager, SceneCache
from service.storage import Storage

from .config import Settings
from .deps import AppState, StoreCache
from .errors import ApiError, clean_validation_errors, error_response, install_error_handlers, summarise
from .routes import health, jobs, render, scenes, stores
from .routes.stores import answer_query
from .schemas import StoreQuery

log = logging.getLogger("render_budget.api")

PUBLIC_PATHS = frozenset({"/health"})


class BearerTokenGuard:
    """Every route but /health (docs and OpenAPI included) needs ``Authorization: Bearer <token>``."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app = app
        self._token = token.encode()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["path"] in PUBLIC_PATHS:
            await self.app(scope, receive, send)
            return
        auth = b""
        for name, value in scope["headers"]:
            if name == b"authorization":
                auth = value
                break
        scheme, _, given = auth.partition(b" ")
        if scheme.lower() == b"bearer" and hmac.compare_digest(given.strip(), self._token):
            await self.app(scope, receive, send)
            return
        message = "missing bearer token" if not auth else "invalid bearer token"
        response = error_response(401, message, headers={"WWW-Authenticate": "Bearer"})
        await response(scope, receive, send)


class BodyTooLarge(StarletteHTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body exceeds the limit of {limit} bytes")


class BodySizeGuard:
    """Reject bodies over the limit before reading them (Content-Length) or as soon as they pass it."""

    def __init__(self, app: ASGIApp, *, default_limit: int, upload_limit: int) -> None:
        self.app = app
        self.default_limit = default_limit
        self.upload_limit = upload_limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        upload = scope["method"] == "POST" and scope["path"].rstrip("/") == "/scenes"
        limit = self.upload_limit if upload else self.default_limit
        for name, value in scope["headers"]:
            if name == b"content-length":
                try:
                    declared = int(value)
                except ValueError:
                    await error_response(400, "invalid Content-Length header")(scope, receive, send)
                    return
                if declared > limit:
                    await error_response(413, f"request body of {declared} bytes exceeds the limit of "
                                              f"{limit} bytes")(scope, receive, send)
                    return
        received = 0

        async def limited() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise BodyTooLarge(limit)
            return message

        await self.app(scope, limited, send)


_QUERY_PATH = re.compile(r"^/stores/([^/]+)/query$")


class QueryFastPath:
    """``POST /stores/{id}/query`` without FastAPI's routing and dependency machinery (the hot path of a
    runtime asking for settings every frame). Same model, same lookup, same answers and error shapes as
    the documented route (tested); anything but a JSON body falls through to that route."""

    def __init__(self, app: ASGIApp, *, stores: Callable[[], StoreCache]) -> None:
        self.app = app
        self._stores = stores

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        match = _QUERY_PATH.match(scope["path"]) if scope["type"] == "http" else None
        if match is None or scope["method"] != "POST" or not _is_json(scope["headers"]):
            await self.app(scope, receive, send)
            return
        chunks = []
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return  # client went away
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        try:
            body = StoreQuery.model_validate_json(b"".join(chunks))
            result = answer_query(self._stores().get(match.group(1)), body)
        except ValidationError as exc:
            details = [{**d, "loc": ["body", *d["loc"]]} for d in clean_validation_errors(list(exc.errors()))]
            response: Response = error_response(422, summarise(details), details=details)
        except ApiError as exc:
            response = error_response(exc.status, exc.message, code=exc.code, details=exc.details)
        else:
            response = Response(result.model_dump_json(), media_type="application/json")
        await response(scope, receive, send)


def _is_json(headers: list[tuple[bytes, bytes]]) -> bool:
    for name, value in headers:
        if name == b"content-type":
            return value.split(b";")[0].strip().lower() == b"application/json"
    return False


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
                             eval_workers=settings.eval_workers,
                             ship_scenes=settings.dask_ship_scenes)
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
    for module in (health, scenes, jobs, stores, render):
        app.include_router(module.router)
    if settings.query_fast_path:
        app.add_middleware(QueryFastPath, stores=lambda: app.state.render_budget.stores)
    app.add_middleware(BodySizeGuard, default_limit=settings.max_body_bytes,
                       upload_limit=settings.max_upload_bytes)
    if settings.token is not None:
        app.add_middleware(BearerTokenGuard, token=settings.token.get_secret_value())
    return app
