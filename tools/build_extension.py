"""Build the Blender extension zip: addon/ plus this project's own wheel (the native core, `sim_core`,
and `service`) and the wheels of the few runtime dependencies the add-on's local path needs, listed in the
staged manifest's `wheels = [...]` and `platforms = [...]`; then Blender's own extension build
(`blender --command extension build`, or its CLI script inside the bpy module) validates and zips it.

    python tools/build_extension.py --out dist/          # dist/render_budget-<version>-<platform>.zip
    python tools/build_extension.py --stage-only DIR     # the add-on folder alone (no wheels: dev loading)

A release for other platforms: build this project's wheel on each OS/arch (`pip wheel . --no-deps`), then
run once with every wheel and platform; Blender's build writes one zip per platform:

    python tools/build_extension.py --out dist/ --own-wheel linux.whl --own-wheel win.whl \\
        --platform linux-x64 --platform windows-x64

Blender's Python is 3.11 from 4.2 LTS to 5.0 (5.1 moves to 3.13), so wheels are collected for CPython 3.11
and the manifest caps `blender_version_max`. numpy is never shipped: Blender bundles its own (1.26.x in
4.2-5.0) and a second copy in the extension's site-packages would shadow it for every add-on.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path
from platform import machine as platform_machine

REPO_ROOT = Path(__file__).resolve().parent.parent
ADDON_DIR = REPO_ROOT / "addon"
PYPROJECT = REPO_ROOT / "pyproject.toml"
WHEEL_CACHE = REPO_ROOT / "build" / "extension-wheels"
PYTHON_VERSION = "3.11"
ABI = "cp311"
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "tests")

#: Blender platform name -> the pip platform tag to download runtime wheels for (pip widens it to the
#: older compatible tags). Linux and macOS minimums are Blender 4.2's (glibc 2.28, macOS 11).
PIP_PLATFORMS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "linux-arm64": "manylinux_2_28_aarch64",
    "macos-x64": "macosx_11_0_x86_64",
    "macos-arm64": "macosx_11_0_arm64",
    "windows-x64": "win_amd64",
    "windows-arm64": "win_arm64",
}
_MACHINES = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64", "arm64": "arm64"}


def manifest() -> dict:
    with (ADDON_DIR / "blender_manifest.toml").open("rb") as fh:
        return tomllib.load(fh)


def pyproject() -> dict:
    with PYPROJECT.open("rb") as fh:
        return tomllib.load(fh)


def this_platform() -> str:
    """Blender's name for the platform this build runs on (e.g. linux-x64)."""
    system = {"darwin": "macos", "win32": "windows"}.get(sys.platform, sys.platform.rstrip("0123456789"))
    machine = platform_machine().lower()
    return f"{system}-{_MACHINES.get(machine, machine)}"


def wheel_platforms(wheel: str | Path) -> set[str]:
    """Blender platforms a wheel installs on, from its file name's platform tag(s)."""
    tags = Path(wheel).name[: -len(".whl")].split("-")[-1].split(".")
    out: set[str] = set()
    for tag in tags:
        if tag == "any":
            return set(PIP_PLATFORMS)
        head, _, tail = tag.partition("_")
        system = ("linux" if head.startswith(("linux", "manylinux", "musllinux")) else
                  "macos" if head == "macosx" else "windows" if head.startswith("win") else head)
        machine = next((m for m in _MACHINES if tail == m or tail.endswith("_" + m)),
                       "x86" if head == "win32" else tail.rpartition("_")[2])
        if system == "macos" and machine == "universal2":
            out |= {"macos-x64", "macos-arm64"}
            continue
        out.add(f"{system}-{_MACHINES.get(machine, machine)}")
    return out


def runtime_requirements() -> list[str]:
    """`name==version` of every runtime wheel the extension carries: the names come from
    [tool.render-budget.extension] runtime-wheels, the pinned versions from [project].dependencies."""
    data = pyproject()
    names = data["tool"]["render-budget"]["extension"]["runtime-wheels"]
    pins = {}
    for dep in data["project"]["dependencies"]:
        m = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)\s*==\s*([^\s;]+)\s*", dep)
        if m:
            pins[_normalise(m.group(1))] = f"{m.group(1)}=={m.group(2)}"
    out = []
    for name in names:
        if _normalise(name) == "numpy":
            raise ValueError("numpy must not be shipped in the extension: Blender bundles its own")
        if _normalise(name) not in pins:
            raise ValueError(f"runtime wheel {name!r} is not pinned with == in [project].dependencies")
        out.append(pins[_normalise(name)])
    return out


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def build_own_wheel(dest: Path) -> Path:
    """This project's wheel for the running interpreter's platform, through the normal package build
    (scikit-build-core; the CMake build folder is reused, so a rebuild only relinks what changed)."""
    dest.mkdir(parents=True, exist_ok=True)
    for old in dest.glob("render_budget-*.whl"):
        old.unlink()
    cmd = [sys.executable, "-m", "pip", "wheel", str(REPO_ROOT), "--no-deps", "--no-build-isolation",
           "--wheel-dir", str(dest), "--quiet"]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    found = sorted(dest.glob("render_budget-*.whl"))
    if proc.returncode != 0 or len(found) != 1:
        raise RuntimeError(f"building the project's wheel failed ({proc.returncode}):\n{proc.stdout}\n"
                           f"{proc.stderr}")
    return found[0]


def collect_runtime_wheels(platforms: list[str], dest: Path = WHEEL_CACHE) -> list[Path]:
    """Wheels of the runtime requirements for CPython 3.11 on each platform (kept in `dest`: a later
    build finds them there and needs no network)."""
    dest.mkdir(parents=True, exist_ok=True)
    wheels: list[Path] = []
    for requirement in runtime_requirements():
        name, version = requirement.split("==")
        for platform in platforms:
            have = _cached(dest, name, version, platform)
            if not have:
                cmd = [sys.executable, "-m", "pip", "download", requirement, "--no-deps",
                       "--only-binary=:all:", "--python-version", PYTHON_VERSION, "--implementation", "cp",
                       "--abi", ABI, "--platform", PIP_PLATFORMS[platform], "--dest", str(dest), "--quiet"]
                proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
                have = _cached(dest, name, version, platform)
                if proc.returncode != 0 or not have:
                    raise RuntimeError(f"no {requirement} wheel for Python {PYTHON_VERSION} on {platform}:\n"
                                       f"{proc.stdout}\n{proc.stderr}")
            wheels.extend(w for w in have[:1] if w not in wheels)
    return wheels


def _cached(dest: Path, name: str, version: str, platform: str) -> list[Path]:
    return sorted(w for w in dest.glob("*.whl")
                  if _normalise(w.name.split("-")[0]) == _normalise(name) and w.name.split("-")[1] == version
                  and platform in wheel_platforms(w))


def _set_manifest_lists(manifest_path: Path, values: dict[str, list[str]]) -> None:
    """Write top-level list keys into the staged manifest (before its first table, so TOML keeps them
    top-level) and check the result still parses with the values given."""
    text = manifest_path.read_text(encoding="utf-8")
    for key in values:
        if re.search(rf"(?m)^\s*{key}\s*=", text):
            raise ValueError(f"addon/blender_manifest.toml must not set {key!r}: the build writes it")
    lines = "".join(f"{key} = [{', '.join(repr(v).replace(chr(39), chr(34)) for v in vals)}]\n"
                    for key, vals in values.items())
    m = re.search(r"(?m)^\[", text)
    at = m.start() if m else len(text)
    text = text[:at] + lines + "\n" + text[at:]
    manifest_path.write_text(text, encoding="utf-8")
    with manifest_path.open("rb") as fh:
        parsed = tomllib.load(fh)
    for key, vals in values.items():
        if parsed.get(key) != vals:
            raise RuntimeError(f"writing {key} into the manifest failed")


def stage(dest_parent: str | Path, wheels: list[Path] | None = None, platforms: list[str] | None = None
          ) -> Path:
    """Copy the extension into `dest_parent/<id>/`; with `wheels`, copy them into `wheels/` and list them
    (and `platforms`) in the staged manifest. Returns that folder."""
    ext_id = manifest()["id"]
    dest = Path(dest_parent) / ext_id
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(ADDON_DIR, dest, ignore=_IGNORE)
    if wheels:
        (dest / "wheels").mkdir()
        for w in wheels:
            shutil.copy2(w, dest / "wheels" / w.name)
        values = {"wheels": [f"./wheels/{w.name}" for w in wheels]}
        if platforms:
            values["platforms"] = list(platforms)
        _set_manifest_lists(dest / "blender_manifest.toml", values)
    return dest


def blender_ext_cli() -> list[str]:
    """Command prefix for Blender's extension CLI: a `blender` binary if present, else the bpy module's."""
    blender = shutil.which("blender")
    if blender:
        return [blender, "--factory-startup", "--command", "extension"]
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("neither a `blender` binary nor the bpy module was found")
    bpy_dir = Path(next(iter(spec.submodule_search_locations)))
    found = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise FileNotFoundError(f"blender_ext.py not found under {bpy_dir}")
    return [sys.executable, str(found[-1])]


def _valid_tags_args(cli: list[str]) -> list[str]:
    """Check tags against Blender's own list, as `blender --command extension build` does."""
    if cli[0] != sys.executable:
        return []
    scripts = Path(cli[1]).parents[3]
    tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    return [f"--valid-tags={tags}"] if tags.is_file() else []


def build(out_dir: str | Path, *, platforms: list[str] | None = None,
          own_wheels: list[str | Path] | None = None) -> list[Path]:
    """Stage with every wheel and build one zip per platform; returns the zips.

    Without `own_wheels` this project's wheel is built here, for this platform only."""
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    m = manifest()
    with tempfile.TemporaryDirectory(prefix="render-budget-ext-") as tmp:
        if own_wheels:
            own = [Path(w).resolve() for w in own_wheels]
        else:
            own = [build_own_wheel(Path(tmp) / "own")]
        own_platforms = {p: w for w in own for p in wheel_platforms(w)}
        platforms = list(platforms or sorted(own_platforms))
        unknown = [p for p in platforms if p not in PIP_PLATFORMS]
        if unknown:
            raise ValueError(f"unknown platform(s) {unknown}; known: {sorted(PIP_PLATFORMS)}")
        missing = [p for p in platforms if p not in own_platforms]
        if missing:
            raise ValueError(f"no render_budget wheel for {missing}: build one there (pip wheel . "
                             "--no-deps) and pass it with --own-wheel")
        wheels = [*own, *collect_runtime_wheels(platforms)]
        src = stage(Path(tmp) / "stage", wheels, platforms)
        for p in platforms:
            stale = out_dir / f"{m['id']}-{m['version']}-{p.replace('-', '_')}.zip"
            stale.unlink(missing_ok=True)
        cli = blender_ext_cli()
        cmd = [*cli, "build", "--source-dir", str(src), "--output-dir", str(out_dir), "--split-platforms",
               *_valid_tags_args(cli)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        zips = [out_dir / f"{m['id']}-{m['version']}-{p.replace('-', '_')}.zip" for p in platforms]
        if proc.returncode != 0 or not all(z.is_file() for z in zips):
            raise RuntimeError(f"extension build failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return zips


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--out", help="output folder for the zip(s)")
    g.add_argument("--stage-only", help="only stage the extension folder (no wheels) under this folder")
    ap.add_argument("--platform", action="append", choices=sorted(PIP_PLATFORMS),
                    help="Blender platform to build for (repeatable; default: the own wheels' platforms)")
    ap.add_argument("--own-wheel", action="append",
                    help="a prebuilt render_budget wheel (repeatable, one per platform; default: build one "
                         "for this platform)")
    args = ap.parse_args(argv)
    if args.stage_only:
        paths = [stage(args.stage_only)]
    else:
        paths = build(args.out, platforms=args.platform, own_wheels=args.own_wheel)
    for path in paths:
        size = path.stat().st_size if path.is_file() else 0
        sys.stdout.write(f"{path}" + (f" ({size / 1e6:.1f} MB)" if size else "") + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
