"""A virtual environment that holds only bpy (and what bpy itself needs), never this project: the stand-in
for a stock Blender in the extension tests. It is kept in build/bpy-venv-<version>/ between runs (a clean
clone creates it on first use with uv, from its cache when warm) and shared by parallel test workers
through a lock."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parent.parent


def bpy_requirement() -> str:
    """The bpy pin of the ``blender`` extra (pyproject.toml is the one place versions live)."""
    with (REPO_ROOT / "pyproject.toml").open("rb") as fh:
        deps = tomllib.load(fh)["project"]["optional-dependencies"]["blender"]
    [pin] = [d for d in deps if d.replace(" ", "").lower().startswith("bpy==")]
    return pin.replace(" ", "")


def venv_dir() -> Path:
    return REPO_ROOT / "build" / f"bpy-venv-{bpy_requirement().split('==')[1]}"


def clean_env(**extra: str) -> dict[str, str]:
    """The environment for processes of that venv: nothing of this project's venv or sources leaks in."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP", "BLENDER_USER_RESOURCES")}
    env.update(extra)
    return env


def python() -> Path:
    """The venv's interpreter, creating the venv first if needed."""
    venv = venv_dir()
    exe = venv / "bin" / "python"
    stamp = venv / ".bpy-only"
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / f".{venv.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (stamp.is_file() and exe.is_file()):
            if venv.exists():
                subprocess.run(["rm", "-rf", str(venv)], check=True)
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, env=clean_env())
            # uv, the installer that set up this project's venv (Makefile): bpy from its cache in seconds.
            uv = Path(sys.executable).parent / "uv"
            install = [str(uv), "pip", "install", "--quiet", "--python", str(exe), bpy_requirement()]
            proc = subprocess.run(install, capture_output=True, text=True, env=clean_env(), check=False)
            if proc.returncode != 0:
                raise RuntimeError(f"could not install {bpy_requirement()} into {venv}:\n{proc.stderr}")
            freeze = subprocess.run([str(exe), "-m", "pip", "freeze"], capture_output=True, text=True,
                                    env=clean_env(), check=True).stdout
            stamp.write_text(freeze, encoding="utf-8")
    return exe


def installed() -> list[str]:
    """`pip freeze` of the venv as recorded when it was made."""
    return (venv_dir() / ".bpy-only").read_text(encoding="utf-8").split()


def run_script(script: str, args: list[str], user_dir: Path, cwd: Path, timeout_s: float = 600,
               prefix: list[str] | None = None) -> tuple[dict[str, Any], str]:
    """Run `script` with the venv's Python in background Blender terms: a fresh Blender user folder
    (BLENDER_USER_RESOURCES set before bpy is imported), the working folder `cwd` (not the repository,
    whose sources must not be importable). The script prints one line `RESULT <json>`.

    Python's fault handler is on, so a crash prints every thread's stack. A run killed by a signal is run
    once more from a fresh user folder, with a warning that carries the crash: a clean-machine run once
    died of SIGSEGV inside bpy during Optimize Power and 18 local runs (one under valgrind) did not; a
    second crash fails the test."""
    path = cwd / "script.py"
    path.write_text(script, encoding="utf-8")
    command = [*(prefix or []), str(python()), "-X", "faulthandler", "-u", str(path), *args]
    for attempt in (1, 2):
        proc = subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=timeout_s,
                              check=False, env=clean_env(BLENDER_USER_RESOURCES=str(user_dir)))
        log = f"exit {proc.returncode}\n--- stdout\n{proc.stdout[-6000:]}\n--- stderr\n{proc.stderr[-6000:]}"
        if proc.returncode >= 0 or attempt == 2:
            break
        warnings.warn(f"the bpy process died of signal {-proc.returncode}; running it once more:\n{log}",
                      stacklevel=2)
        shutil.rmtree(user_dir, ignore_errors=True)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise AssertionError(log)
    return json.loads(lines[-1][len("RESULT "):]), log
