"""A route FastAPI documents from its endpoint's signature but serves without its per-request
dependency machinery: for ``POST /stores/{id}/query``, the call a runtime makes every frame.

The endpoint takes ``str`` path parameters, one pydantic body model and optionally ``request: Request``
(nothing else to solve) and returns its response model. The body is validated by pydantic straight from
the bytes and the answer serialised by pydantic, so validation, status codes and error shapes are those
of any other route; only FastAPI's generic parameter solving and response re-validation are skipped
(about 3x less time per query, bench/RESULTS.md)."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from pydantic import BaseModel, ValidationError
from starlette.requests import Request
from starlette.responses import Response


def is_json(content_type: str) -> bool:
    """``application/json`` or ``application/*+json`` (parameters such as charset ignored)."""
    kind = content_type.split(";", 1)[0].strip().lower()
    return kind == "application/json" or (kind.startswith("application/") and kind.endswith("+json"))


class LeanJsonRoute(APIRoute):
    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        dependant = self.dependant
        if (dependant.dependencies or dependant.query_params or dependant.header_params
                or dependant.cookie_params or self.body_field is None):
            raise TypeError(f"{self.path}: a lean route takes path parameters, one JSON body and the request")
        model = self.body_field.field_info.annotation
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            raise TypeError(f"{self.path}: the body of a lean route must be a pydantic model")
        body_name = self.body_field.name
        path_names = [p.name for p in dependant.path_params]
        request_name = dependant.request_param_name
        endpoint = self.endpoint
        status = self.status_code or 200

        async def handler(request: Request) -> Response:
            if not is_json(request.headers.get("content-type", "")):
                raise RequestValidationError([{"type": "model_attributes_type", "loc": ("body",), "msg":
                                               "the body must be JSON (Content-Type: application/json)"}])
            try:
                body = model.model_validate_json(await request.body())
            except ValidationError as exc:
                raise RequestValidationError(
                    [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]) from None
            kwargs: dict[str, Any] = {name: request.path_params[name] for name in path_names}
            kwargs[body_name] = body
            if request_name is not None:
                kwargs[request_name] = request
            result: BaseModel = await endpoint(**kwargs)
            return Response(result.model_dump_json(), status_code=status, media_type="application/json")

        return handler
