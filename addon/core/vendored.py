"""Access to the service modules the build step copies into the extension (`_vendored/`).

In the built extension they are `<package>._vendored.pareto_store` / `.camera_path` / `.options`; when
the pure core is imported from the source tree (tests, `python -m addon.batch`) the originals in
`service/` are used. There is only ever one implementation of the store format and the option schema.
"""

from __future__ import annotations

try:  # built extension
    from .._vendored import camera_path, options, pareto_store
except ImportError:  # source tree
    from service import camera_path, options, pareto_store  # type: ignore[no-redef]

__all__ = ["camera_path", "options", "pareto_store"]
