"""The native core is built and importable from the package, its files keep one stem per concept, and the
venv was set up with the tools pinned in pyproject.toml."""

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import sim_core
from tools import pins

REPO = Path(__file__).resolve().parent.parent
NATIVE = REPO / "sim_core"


def test_native_core_version_matches_package() -> None:
    assert sim_core.__version__ == "0.1.0"


def test_native_files_share_concept_stems() -> None:
    """src/<c>.cpp, src/python/<c>_py.cpp and tests/<c>_test.cpp each belong to a header <c>.h, and the
    module entry binds every concept through its own file's bind_<c>."""
    headers = {p.stem for p in (NATIVE / "include" / "sim_core").glob("*.h")}
    sources = {p.stem for p in (NATIVE / "src").glob("*.cpp")}
    bindings = {p.stem.removesuffix("_py") for p in (NATIVE / "src" / "python").glob("*_py.cpp")}
    tests = {p.stem.removesuffix("_test") for p in (NATIVE / "tests").glob("*_test.cpp")}
    assert sources <= headers, sources - headers
    assert bindings <= headers, bindings - headers
    assert tests <= headers, tests - headers
    module = (NATIVE / "src" / "python" / "module.cpp").read_text()
    called = set(re.findall(r"sim_core::bind_(\w+)\(m\)", module))
    assert called == bindings
    for stem in bindings:
        text = (NATIVE / "src" / "python" / f"{stem}_py.cpp").read_text()
        assert re.search(rf"void bind_{stem}\(nb::module_& m\)", text), stem
        assert set(re.findall(r"void bind_(\w+)\(", text)) == {stem}, stem


def test_set_up_pins_come_from_pyproject() -> None:
    """The Makefile installs what tools/pins.py prints: every pin in pyproject.toml, exact versions, and the
    venv running these tests holds exactly those versions."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    bootstrap = project["tool"]["render-budget"]["bootstrap"]
    assert pins.pins("installer") == [bootstrap["installer"]]
    assert pins.pins("build") == [*project["build-system"]["requires"], *bootstrap["build-tools"]]
    for requirement in pins.pins("installer") + pins.pins("build"):
        name, version = requirement.split("==")
        assert metadata.version(name) == version, requirement
    with pytest.raises(SystemExit, match="unknown step"):
        pins.pins("everything")
