"""Prints the pinned requirements of one set-up step, read from pyproject.toml (the one place pins live).

    python tools/pins.py installer   # the installer that sets up .venv (uv)
    python tools/pins.py build       # the native build's requirements and the build tools (cmake, ninja)

Standard library only: the Makefile runs it in a bare venv, before anything is installed.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"


def pins(step: str) -> list[str]:
    with PYPROJECT.open("rb") as fh:
        project = tomllib.load(fh)
    bootstrap = project["tool"]["render-budget"]["bootstrap"]
    steps = {
        "installer": [bootstrap["installer"]],
        "build": [*project["build-system"]["requires"], *bootstrap["build-tools"]],
    }
    if step not in steps:
        raise SystemExit(f"unknown step {step!r}: one of {', '.join(steps)}")
    return steps[step]


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    sys.stdout.write(" ".join(pins(sys.argv[1])) + "\n")
