"""Access to the service modules the build step copies into the extension (`_vendored/`).

In the built extension they are `<package>._vendored.store` (the store package, here under the name
`pareto_store`), `.camera_path` and `.options`; when the pure core is imported from the source tree
(tests, `python -m addon.batch`) the originals in `service/` are used. There is only ever one
implementation of the store format, the camera maths and the option schema.
"""

from __future__ import annotations

try:  # built extension
    from .._vendored import camera_path, options
    from .._vendored import store as pareto_store
    from .._vendored.store import camera
except ImportError:  # source tree
    from service import camera_path, options  # type: ignore[no-redef]
    from service import store as pareto_store  # type: ignore[no-redef]
    from service.store import camera  # type: ignore[no-redef]

__all__ = ["camera", "camera_path", "options", "pareto_store"]
