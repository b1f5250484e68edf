"""The extension zip: built by Blender's own extension tooling, installed into a fresh Blender user folder
through the Extensions system, enabled, disabled and re-enabled without leftovers (separate process, so
the installed copy never meets the dev copy other tests load)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.addon_support import REPO_ROOT, build_extension

pytestmark = pytest.mark.blender

SCRIPT = r"""
import json, sys
import bpy, addon_utils
zip_path = sys.argv[1]
mod = "bl_ext.user_default.render_budget"
out = {}
res = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
out["install"] = sorted(res)
def state():
    names = [n for n in dir(bpy.types) if n.startswith(("RENDER_BUDGET_", "VIEW3D_PT_render_budget"))]
    handlers = [h.__module__ for hs in (bpy.app.handlers.frame_change_post, bpy.app.handlers.load_post)
                for h in hs if (getattr(h, "__module__", "") or "").startswith(mod)]
    return {"enabled": mod in bpy.context.preferences.addons, "types": len(names), "handlers": handlers,
            "scene_prop": hasattr(bpy.types.Scene, "render_budget"),
            "wm_prop": hasattr(bpy.types.WindowManager, "render_budget_runtime")}
out["after_install"] = state()
import importlib
ps = importlib.import_module(mod + "._vendored.store")
out["vendored_store"] = ps.FORMAT_NAME
out["hud"] = importlib.import_module(mod + ".hud").is_registered()
addon_utils.disable(mod, default_set=True)
out["after_disable"] = state()
addon_utils.enable(mod, default_set=True)
out["after_reenable"] = state()
addon_utils.disable(mod, default_set=True)
out["after_second_disable"] = state()
sys.stdout.write("RESULT " + json.dumps(out) + "\n")
"""


@pytest.fixture(scope="module")
def zip_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_extension.build(tmp_path_factory.mktemp("dist"))


def test_zip_contains_addon_and_vendored_store(zip_path: Path) -> None:
    names = set(zipfile.ZipFile(zip_path).namelist())
    for required in ("blender_manifest.toml", "__init__.py", "core/client.py", "playback.py", "hud.py",
                     "_vendored/store/__init__.py", "_vendored/store/camera.py", "_vendored/camera_path.py",
                     "_vendored/options.py"):
        assert required in names
    assert not any("__pycache__" in n for n in names)
    # the vendored files are byte copies of the service modules (one implementation)
    z = zipfile.ZipFile(zip_path)
    service = REPO_ROOT / "service"
    store_files = sorted((service / "store").glob("*.py"))
    for src in [service / "camera_path.py", service / "options.py", *store_files]:
        assert z.read(f"_vendored/{src.relative_to(service).as_posix()}") == src.read_bytes()


def test_manifest_rejects_a_trailing_full_stop(tmp_path: Path) -> None:
    """Blender's own validator runs in the build: a bad manifest fails the build loudly."""
    src = build_extension.stage(tmp_path / "stage")
    manifest = src / "blender_manifest.toml"
    text = manifest.read_text()
    manifest.write_text(text.replace('ray-tracing settings along a camera path"',
                                     'ray-tracing settings along a camera path."'))
    cli = build_extension.blender_ext_cli()
    proc = subprocess.run([*cli, "build", "--source-dir", str(src), "--output-dir", str(tmp_path)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode != 0 and "tagline" in (proc.stdout + proc.stderr)


def test_zip_installs_enables_disables_and_reenables_cleanly(zip_path: Path, tmp_path: Path) -> None:
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(zip_path)], capture_output=True, text=True,
                          env=env, timeout=300, check=False)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout + proc.stderr
    out = json.loads(lines[-1][len("RESULT "):])
    assert out["install"] == ["FINISHED"]
    on, off = out["after_install"], out["after_disable"]
    assert on["enabled"] and on["types"] >= 10 and on["scene_prop"] and on["wm_prop"]
    assert len(on["handlers"]) == 3  # playback: frame change + load; migration: load
    assert out["vendored_store"] == "render-budget/pareto-store" and out["hud"] is False
    for st in (off, out["after_second_disable"]):
        assert st == {"enabled": False, "types": 0, "handlers": [], "scene_prop": False, "wm_prop": False}
    assert out["after_reenable"] == on
