"""The runtime Pareto store, as a small package (stdlib + numpy only: the Blender add-on carries it).

- :mod:`.packing`: settings as 4-bit value indices packed in 32 bits, and the parameter descriptions;
- :mod:`.frame_rate`: the frame-rate rule (a setting meets the store's fps, the frame rate it reaches);
- :mod:`.frontier`: a Pareto frontier (meeting and slow tiers) and its budget searches;
- :mod:`.codec`: how numbers are kept (base64 arrays, bit-packed integers, 16-bit steps, direction and
  eye codes);
- :mod:`.format`: the versioned JSON document (reads versions 1-6, writes 6, or 5 on request);
- :mod:`.camera`: camera maths shared by every part of the project (rotations, view-cube faces,
  frustum face choice, field of view);
- :mod:`.lookup`: camera pose + budget -> settings;
- :mod:`.figures`: where the store's figures were measured (display or preview size), for their labels;
- :mod:`.pareto`: :class:`ParetoStore`, the store itself;
- :mod:`.temporal`: the temporal filter (Eq. 8) applied during playback.
"""

from __future__ import annotations

from .camera import VIEW_FORWARD, VIEW_NAMES, VIEW_UP, camera_rotation, face_of, view_up
from .codec import quantise_directions, quantise_eyes
from .figures import FiguresSize
from .format import FORMAT_NAME, FORMAT_VERSION, READABLE_VERSIONS
from .frame_rate import frame_rate_reached, meets_frame_rate
from .frontier import Frontier, frontier_tiers, split_by_rate
from .lookup import LookupResult
from .packing import (
    BITS_PER_PARAM,
    MAX_PARAMS,
    MAX_VALUES_PER_PARAM,
    StoredParameter,
    pack_array,
    pack_indices,
    unpack_array,
    unpack_indices,
)
from .pareto import ParetoStore
from .temporal import TemporalFilter

__all__ = [
    "BITS_PER_PARAM", "FORMAT_NAME", "FORMAT_VERSION", "MAX_PARAMS", "MAX_VALUES_PER_PARAM",
    "READABLE_VERSIONS", "VIEW_FORWARD", "VIEW_NAMES", "VIEW_UP", "FiguresSize", "Frontier", "LookupResult",
    "ParetoStore", "StoredParameter", "TemporalFilter", "camera_rotation", "face_of", "frame_rate_reached",
    "frontier_tiers",
    "meets_frame_rate", "pack_array", "pack_indices", "quantise_directions", "quantise_eyes", "split_by_rate",
    "unpack_array", "unpack_indices", "view_up",
]
