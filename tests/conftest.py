"""Shared test set-up: keep Blender's user files out of the home directory, find bundled assets."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

# Must happen before any test module imports bpy (Blender reads it at import time).
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="render-budget-blender-"))

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
