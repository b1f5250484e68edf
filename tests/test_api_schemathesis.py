"""Property-based fuzzing of the service's own OpenAPI (schemathesis): no input causes a server error."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import schemathesis
from api_support import server_thread
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode

from service.api import Settings

pytestmark = pytest.mark.service

EXAMPLES_PER_MODE = 12


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data = tmp_path_factory.mktemp("api-fuzz")
    with server_thread(Settings(data_dir=data, job_workers=1, max_upload_bytes=1 << 20)) as url:
        yield url


def test_openapi_fuzzing_finds_no_server_error(base: str, tmp_path: Path) -> None:
    schema = schemathesis.openapi.from_url(f"{base}/openapi.json")
    operations = [r.ok() for r in schema.get_all_operations()]
    assert len(operations) >= 10
    seen: dict[str, set[int]] = {}

    for op in operations:
        for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):

            @settings(max_examples=EXAMPLES_PER_MODE, deadline=None, database=None, derandomize=True,
                      suppress_health_check=list(HealthCheck))
            @given(case=op.as_strategy(generation_mode=mode))
            def check(case: schemathesis.Case) -> None:
                response = case.call(base_url=base, timeout=30)
                assert response.status_code < 500, (case.method, case.path, response.text)
                seen.setdefault(case.operation.label, set()).add(response.status_code)
                if response.status_code >= 400:
                    body = response.json()
                    assert set(body["error"]) == {"status", "code", "message", "details"}

            try:
                check()
            except Unsatisfiable:
                # No negative input exists for operations without parameters (GET /health).
                assert mode == GenerationMode.NEGATIVE
    assert len(seen) == len(operations)
    # The server is still healthy and wrote nothing outside its data directory.
    assert httpx.get(f"{base}/health").status_code == 200
    assert list(tmp_path.iterdir()) == []
