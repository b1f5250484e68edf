"""OpenAPI links: which later request a response's fields feed (clients and stateful fuzzers follow them)."""

from __future__ import annotations

from typing import Any


def links(**targets: tuple[str, str, str]) -> dict[str, Any]:
    """``Name=(operation_id, parameter, response field)`` -> the OpenAPI ``links`` of a response."""
    return {name: {"operationId": operation, "parameters": {parameter: f"$response.body#/{field}"}}
            for name, (operation, parameter, field) in targets.items()}
