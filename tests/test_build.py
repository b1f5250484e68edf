"""The native core is built and importable from the package."""

import sim_core


def test_native_core_version_matches_package() -> None:
    assert sim_core.__version__ == "0.1.0"
