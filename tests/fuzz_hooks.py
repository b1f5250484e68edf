"""Schemathesis hooks for the service's fuzz run: half the generated ids become real ones (a scene, a
store and a finished job the test made, named in RENDER_BUDGET_FUZZ_* variables), so requests reach the
renderer, the evaluator and the store lookup instead of stopping at 404. Only well-formed ids are
replaced (a negative case stays negative), and a DELETE never gets a real one (schemathesis also takes
ids from listings: deleting the real ones early would turn the rest of the run into 404s)."""

from __future__ import annotations

import os
import re
from typing import Any

import schemathesis

_REAL = {"scene_id": os.environ.get("RENDER_BUDGET_FUZZ_SCENE", ""),
         "store_id": os.environ.get("RENDER_BUDGET_FUZZ_STORE", ""),
         "job_id": os.environ.get("RENDER_BUDGET_FUZZ_JOB", "")}
_SCENE_ID = re.compile(r"^[0-9a-f]{64}$")


_seen: dict[str, int] = {}


def _pick(name: str) -> bool:
    """Every other case that has this id (deterministic: the run is seeded and single-worker)."""
    _seen[name] = _seen.get(name, 0) + 1
    return _seen[name] % 2 == 0


@schemathesis.hook
def map_case(ctx: Any, case: Any) -> Any:
    if str(case.method).upper() == "DELETE":  # ids found in listings are fuzzed too: spare the real ones
        for name, value in (case.path_parameters or {}).items():
            if value and value == _REAL.get(name):
                case.path_parameters = {**case.path_parameters, name: "0" * len(value)}
        return case
    for name, value in (case.path_parameters or {}).items():
        if _REAL.get(name) and isinstance(value, str) and _pick(name):
            case.path_parameters = {**case.path_parameters, name: _REAL[name]}
    if case.path in ("/render", "/evaluate") and isinstance(case.body, dict) and _REAL["scene_id"]:
        value = case.body.get("scene_id")
        if isinstance(value, str) and _SCENE_ID.match(value) and _pick("body scene_id"):
            case.body = {**case.body, "scene_id": _REAL["scene_id"]}
    return case


@schemathesis.hook
def after_call(ctx: Any, case: Any, response: Any) -> None:
    """One line per request, "METHOD path-template status", for the test to see what was reached."""
    log = os.environ.get("RENDER_BUDGET_FUZZ_STATUS_LOG")
    if log:
        with open(log, "a", encoding="utf-8") as f:
            f.write(f"{str(case.method).upper()} {case.path} {response.status_code}\n")
