"""Build the Blender extension zip: stage addon/ plus the shared service modules, then run Blender's
own extension build (`blender --command extension build`, or its CLI script inside the bpy module).

    python tools/build_extension.py --out dist/          # writes dist/render_budget-<version>.zip
    python tools/build_extension.py --stage-only DIR     # staged folder only (for dev loading)

The store format, camera maths and option schema live in one place (the service/store/ package,
service/camera_path.py, service/options.py); this step copies them into the staged extension as
`<id>/_vendored/`, so the source tree never holds two copies.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
ADDON_DIR = REPO_ROOT / "addon"
VENDORED = ("store", "camera_path.py", "options.py")  # files or packages under service/
ALLOWED_VENDORED_IMPORTS = {"numpy", "__future__"}
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "tests")


def manifest() -> dict:
    with (ADDON_DIR / "blender_manifest.toml").open("rb") as fh:
        return tomllib.load(fh)


def _check_vendored_imports(path: Path) -> None:
    """The vendored modules run inside a stock Blender: stdlib + numpy + each other only."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    in_package = path.parent != REPO_ROOT / "service"
    local = {p.stem for p in path.parent.glob("*.py")} if in_package else {Path(v).stem for v in VENDORED}
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name.split(".")[0] for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import: must stay within the vendored modules
                names = [node.module.split(".")[0]] if node.module else [a.name for a in node.names]
                bad = [n for n in names if n not in local]
                if bad:
                    raise ValueError(f"{path.name}: relative import of {bad} cannot be vendored")
                continue
            names = [(node.module or "").split(".")[0]]
        for name in names:
            if name in ALLOWED_VENDORED_IMPORTS or name in sys.stdlib_module_names:
                continue
            raise ValueError(f"{path.name} imports {name!r}: vendored modules may use stdlib + numpy only")


def stage(dest_parent: str | Path) -> Path:
    """Copy the extension into `dest_parent/<id>/` with `_vendored/`; return that folder."""
    ext_id = manifest()["id"]
    dest = Path(dest_parent) / ext_id
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(ADDON_DIR, dest, ignore=_IGNORE)
    vend = dest / "_vendored"
    vend.mkdir()
    (vend / "__init__.py").write_text(
        '"""Copies of service modules made by tools/build_extension.py; do not edit here."""\n',
        encoding="utf-8")
    for name in VENDORED:
        src = REPO_ROOT / "service" / name
        if not src.exists():
            raise FileNotFoundError(f"service/{name} is missing: the extension cannot be built without it")
        for path in sorted(src.glob("*.py")) if src.is_dir() else [src]:
            _check_vendored_imports(path)
        if src.is_dir():
            shutil.copytree(src, vend / name, ignore=_IGNORE)
        else:
            shutil.copy2(src, vend / name)
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


def build(out_dir: str | Path) -> Path:
    """Stage and build; return the path of the zip."""
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    m = manifest()
    zip_path = out_dir / f"{m['id']}-{m['version']}.zip"
    if zip_path.exists():
        zip_path.unlink()
    with tempfile.TemporaryDirectory(prefix="render-budget-ext-") as tmp:
        src = stage(tmp)
        cli = blender_ext_cli()
        cmd = [*cli, "build", "--source-dir", str(src), "--output-filepath", str(zip_path),
               *_valid_tags_args(cli)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0 or not zip_path.is_file():
            raise RuntimeError(f"extension build failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return zip_path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--out", help="output folder for the zip")
    g.add_argument("--stage-only", help="only stage the extension folder under this folder")
    args = ap.parse_args(argv)
    if args.stage_only:
        path = stage(args.stage_only)
    else:
        path = build(args.out)
    sys.stdout.write(f"{path}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
