"""The extension zip: built by Blender's own extension tooling with this project's wheel and its runtime
wheels, installed through the Extensions system into a fresh Blender user folder of a virtual environment
that holds only bpy (never this project), enabled, disabled and re-enabled without leftovers; and the
same zip installed and enabled without network access."""

from __future__ import annotations

import io
import shutil
import subprocess
import tomllib
import zipfile
from pathlib import Path

import pytest

from tests import bpy_venv
from tests.addon_support import REPO_ROOT, build_extension

pytestmark = [pytest.mark.blender, pytest.mark.slow]

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
import service.store, service.local_job, sim_core, PIL.Image, OpenEXR, numpy
out["modules"] = {m.__name__: m.__file__ for m in (service.store, sim_core, PIL.Image, OpenEXR, numpy)}
out["hud"] = importlib.import_module(mod + ".hud").is_registered()
out["health"] = importlib.import_module(mod + ".core.local_jobs").LocalClient("unused").health()
addon_utils.disable(mod, default_set=True)
out["after_disable"] = state()
addon_utils.enable(mod, default_set=True)
out["after_reenable"] = state()
addon_utils.disable(mod, default_set=True)
out["after_second_disable"] = state()
sys.stdout.write("RESULT " + json.dumps(out) + "\n")
"""


@pytest.fixture(scope="module")
def zip_path(extension_zip: Path) -> Path:
    return extension_zip


def test_zip_carries_the_project_wheel_and_its_runtime_wheels(zip_path: Path) -> None:
    z = zipfile.ZipFile(zip_path)
    names = set(z.namelist())
    for required in ("blender_manifest.toml", "__init__.py", "core/client.py", "core/local_jobs.py",
                     "playback.py", "hud.py"):
        assert required in names
    assert not any("__pycache__" in n or "_vendored" in n for n in names)
    manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    wheels = sorted(n for n in names if n.startswith("wheels/"))
    assert sorted(w.removeprefix("./") for w in manifest["wheels"]) == wheels
    by_name = {Path(w).name.split("-")[0].lower(): Path(w).name for w in wheels}
    assert set(by_name) == {"render_budget", "pillow", "openexr"}  # no numpy: Blender's own is used
    pins = {d.split("==")[0].lower(): d.split("==")[1] for d in
            tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]["dependencies"]}
    for name in ("pillow", "openexr"):
        assert by_name[name].split("-")[1] == pins[name]
        assert "-cp311-" in by_name[name]
    assert manifest["platforms"] == [build_extension.this_platform()]
    assert manifest["blender_version_max"] == "5.1.0"  # the wheels are for Python 3.11
    # the project's wheel holds the native core and the service packages the add-on imports
    own = zipfile.ZipFile(io.BytesIO(z.read(f"wheels/{by_name['render_budget']}")))
    own_names = own.namelist()
    assert any(n.startswith("sim_core/_core") for n in own_names)
    for module in ("service/store/pareto.py", "service/local_job.py", "service/optimize.py"):
        assert module in own_names


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


def test_release_build_needs_a_project_wheel_per_platform(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no render_budget wheel for \\['windows-x64'\\]"):
        build_extension.build(tmp_path, platforms=[build_extension.this_platform(), "windows-x64"])
    arm = "x-1-cp311-cp311-manylinux_2_17_aarch64.manylinux2014_aarch64.whl"
    assert build_extension.wheel_platforms(arm) == {"linux-arm64"}
    assert build_extension.wheel_platforms("x-1-cp311-cp311-macosx_10_9_universal2.whl") == \
        {"macos-x64", "macos-arm64"}
    assert build_extension.wheel_platforms("x-1-cp311-cp311-win_amd64.whl") == {"windows-x64"}
    assert build_extension.wheel_platforms("x-1-cp311-cp311-linux_x86_64.whl") == {"linux-x64"}


def test_release_build_writes_one_zip_per_platform(zip_path: Path, tmp_path: Path) -> None:
    """A release: a project wheel per platform (here the Linux one, renamed for Windows: the packaging
    does not look inside), one run, one zip per platform holding only that platform's wheels."""
    own = next(n for n in zipfile.ZipFile(zip_path).namelist() if n.startswith("wheels/render_budget-"))
    linux = tmp_path / Path(own).name
    linux.write_bytes(zipfile.ZipFile(zip_path).read(own))
    windows = tmp_path / linux.name.replace(linux.name.split("-")[-1], "win_amd64.whl")
    shutil.copy(linux, windows)
    zips = build_extension.build(tmp_path / "dist", own_wheels=[linux, windows])
    here = build_extension.this_platform().replace("-", "_")
    assert sorted(z.name for z in zips) == sorted([f"render_budget-0.1.0-{here}.zip",
                                                   "render_budget-0.1.0-windows_x64.zip"])
    for z in zips:
        wheels = [n for n in zipfile.ZipFile(z).namelist() if n.startswith("wheels/")]
        assert len(wheels) == 3 and all(n.endswith("win_amd64.whl") == ("windows" in z.name) for n in wheels)
        assert {Path(n).name.split("-")[0].lower() for n in wheels} == {"render_budget", "pillow", "openexr"}


def _check_install(out: dict, user: Path) -> None:
    assert out["install"] == ["FINISHED"]
    on = out["after_install"]
    assert on["enabled"] and on["types"] >= 10 and on["scene_prop"] and on["wm_prop"]
    assert len(on["handlers"]) == 3  # playback: frame change + load; migration: load
    site = str(user / "extensions" / ".local")
    for name in ("service.store", "sim_core", "PIL.Image", "OpenEXR"):  # the zip's wheels
        assert out["modules"][name].startswith(site), out["modules"]
    assert not out["modules"]["numpy"].startswith(site)  # Blender's (here: bpy's) numpy
    assert out["hud"] is False and out["health"]["status"] == "ok"


def test_zip_installs_enables_disables_and_reenables_cleanly(zip_path: Path, tmp_path: Path) -> None:
    out, _ = bpy_venv.run_script(SCRIPT, [str(zip_path)], tmp_path / "user", tmp_path)
    assert not any(p.lower().startswith("render-budget") for p in bpy_venv.installed())
    _check_install(out, tmp_path / "user")
    for st in (out["after_disable"], out["after_second_disable"]):
        assert st == {"enabled": False, "types": 0, "handlers": [], "scene_prop": False, "wm_prop": False}
    assert out["after_reenable"] == out["after_install"]


def test_zip_installs_and_enables_without_network(zip_path: Path, tmp_path: Path) -> None:
    """In a network namespace with no interface up: everything the extension needs is in the zip."""
    unshare = shutil.which("unshare")
    if unshare is None or subprocess.run([unshare, "-rn", "true"], capture_output=True).returncode != 0:
        pytest.skip("no network namespaces here (unshare -rn)")
    offline = [unshare, "-rn"]
    probe = ("import socket\ntry:\n    socket.create_connection(('pypi.org', 443), timeout=3)\n"
             "    print('RESULT {\"online\": true}')\nexcept OSError:\n"
             "    print('RESULT {\"online\": false}')\n")
    online, _ = bpy_venv.run_script(probe, [], tmp_path / "probe", tmp_path, prefix=offline)
    assert online == {"online": False}
    out, _ = bpy_venv.run_script(SCRIPT, [str(zip_path)], tmp_path / "user", tmp_path, prefix=offline)
    _check_install(out, tmp_path / "user")
