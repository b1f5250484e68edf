"""Shared test set-up: keep Blender's user files out of the home directory, find bundled assets."""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

# Must happen before any test module imports bpy (Blender reads it at import time).
_BLENDER_USER = tempfile.TemporaryDirectory(prefix="render-budget-blender-")  # removed when the run ends
os.environ.setdefault("BLENDER_USER_RESOURCES", _BLENDER_USER.name)

REPO_ROOT = Path(__file__).resolve().parent.parent
MODELS_DIR = REPO_ROOT / "assets" / "models"


@pytest.fixture(scope="session")
def models_dir() -> Path:
    return MODELS_DIR


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The extension zip for this platform, built once per test session (tools/build_extension.py)."""
    from tests.addon_support import build_extension

    [path] = build_extension.build(tmp_path_factory.mktemp("dist"))
    return path


@pytest.fixture
def opened_files() -> Iterator[list[str]]:
    """Every file this process opens while the test runs (Python's ``open`` audit event), resolved; a
    server started with ``api_support.server_thread`` runs in this process too."""
    seen: list[str] = []
    active = [True]

    def hook(event: str, args: tuple[Any, ...]) -> None:
        if active[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
            seen.append(os.path.realpath(os.fsdecode(args[0])))

    sys.addaudithook(hook)  # audit hooks cannot be removed: this one is switched off instead
    yield seen
    active[0] = False
