"""Camera maths, once: orientations from matrices, directions or quaternions, the view cube's faces,
frustum face choice, field of view and aspect.

Used by the store lookup, the camera-path format (:mod:`service.camera_path`), the optimiser, the REST
edge and the Blender add-on; stdlib + numpy only (the add-on carries it).

Conventions: world frame Z up (Blender's); a camera looks down its local -Z with +Y up; a rotation's
columns are (right, up, backward), the upper-left 3x3 of Blender's ``matrix_world``. The view cube
around a point has six faces (cones of directions around the world axes, :data:`VIEW_NAMES`); a
direction belongs to the face of its largest signed component.

It also holds the one set of camera limits (:data:`VFOV_MIN` ... :data:`MIN_AXES_VOLUME`) and their
checks: the REST schemas, camera paths, the store lookup and the renderer's cameras accept the same
cameras, so a camera the service takes never fails later in the simulator.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: The six axis views of a corner's view cube, in storage order.
VIEW_NAMES: tuple[str, ...] = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
#: Forward direction of each view (world frame, Z up).
VIEW_FORWARD = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
#: Up vector used when rendering each view: world +Z for horizontal views, +Y when looking along Z.
VIEW_UP = np.array(
    [[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 1, 0], [0, 1, 0]], dtype=np.float64
)
#: Face of a signed axis in the order +X, +Y, +Z, -X, -Y, -Z (argmax of (d, -d)) -> VIEW_NAMES index.
SIGNED_TO_VIEW = (0, 2, 4, 1, 3, 5)
#: Blender's 3D viewport treats its lens as if the sensor were 72 mm wide (twice a 36 mm camera sensor).
VIEWPORT_SENSOR_MM = 72.0
#: Frustum rays per side sampled to decide which face a camera looks through.
FRUSTUM_SAMPLES = 8

# -- camera limits ----------------------------------------------------------------------------------------
#: Vertical field of view, radians: VFOV_MIN <= vfov < VFOV_MAX. The simulator's camera takes (0, 3.1)
#: in float32, where 3.0999999999999996 is already 3.1: below 3.09 nothing rounds up to it. Blender's
#: own range is 0.0064 .. 3.0168.
VFOV_MIN = 1e-4
VFOV_MAX = 3.09
#: Largest camera coordinate, metres. The simulator computes in float32: positions up to 1e9 keep squared
#: distances (1e18) and their products far from float32's 3.4e38, including the samples placed around a
#: path.
MAX_COORDINATE = 1e9
#: Pixels per side the simulator renders.
MAX_RESOLUTION = 16384
#: Widest and tallest image, width / height and its inverse (sizes derived from a path's aspect, such as
#: its evaluation images, must stay within MAX_RESOLUTION).
MAX_ASPECT = 64.0
#: The camera axes, scaled to unit length, must span at least this volume (the simulator's own test):
#: a camera matrix with (nearly) parallel or zero axes has no orientation.
MIN_AXES_VOLUME = 1e-3


def vec3(v: Any, name: str) -> tuple[float, float, float]:
    """Three finite floats from a sequence or array (plain floats: cheap on the per-frame path)."""
    try:
        if len(v) != 3:
            raise ValueError
        a, b, c = float(v[0]), float(v[1]), float(v[2])
    except (TypeError, ValueError, IndexError) as exc:
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}") from exc
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a, b, c


def _scale_free(v: tuple[float, float, float], name: str) -> tuple[float, float, float]:
    """Divide by the largest component (so squaring cannot overflow); zero vectors are refused."""
    m = max(abs(v[0]), abs(v[1]), abs(v[2]))
    if m == 0.0:  # any other finite vector scales to unit size (even subnormal ones)
        raise ValueError(f"{name} must be non-zero")
    return v[0] / m, v[1] / m, v[2] / m


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


Rotation = tuple[float, float, float, float, float, float, float, float, float]  # 3x3, row-major


def look_rotation(direction: Any, up: Any = None) -> np.ndarray:
    """Rotation (3x3, columns right, up, backward) of a camera looking along ``direction`` with ``up``
    (default world +Z, or +Y when looking within about 0.06 degrees of straight up or down). Any
    finite non-zero lengths; ValueError for zero vectors or an ``up`` parallel to the direction."""
    return np.array(_look_floats(direction, up)).reshape(3, 3)


def _look_floats(direction: Any, up: Any) -> Rotation:
    fx, fy, fz = _scale_free(vec3(direction, "direction"), "direction")
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    fx, fy, fz = fx / n, fy / n, fz / n
    ux, uy, uz = (0.0, 0.0, 1.0) if up is None else _scale_free(vec3(up, "up"), "up")
    r = _cross((fx, fy, fz), (ux, uy, uz))
    rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    if rn < 1e-3 * max(un, 1e-300):
        if up is not None:
            raise ValueError("up must not be parallel to direction")
        r = _cross((fx, fy, fz), (0.0, 1.0, 0.0))
        rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    r = (r[0] / rn, r[1] / rn, r[2] / rn)
    tu = _cross(r, (fx, fy, fz))
    return (r[0], tu[0], -fx, r[1], tu[1], -fy, r[2], tu[2], -fz)


def _matrix_rows(matrix: Any) -> list[list[float]]:
    """A 4x4 or 3x3 matrix as rows of floats (plain Python for lists and arrays: the per-frame path)."""
    rows = None
    if isinstance(matrix, np.ndarray) and matrix.dtype == np.float64:
        if matrix.shape in ((4, 4), (3, 3)):
            rows = matrix.tolist()
    elif isinstance(matrix, (list, tuple)) and len(matrix) in (3, 4):
        try:
            if all(isinstance(r, (list, tuple)) and len(r) == len(matrix) for r in matrix):
                rows = [[float(v) for v in r] for r in matrix]
        except (TypeError, ValueError):
            rows = None  # numpy says what is wrong
    if rows is None:
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape not in ((4, 4), (3, 3)):
            raise ValueError("matrix must be a finite 4x4 or 3x3 array")
        rows = m.tolist()
    if not all(math.isfinite(v) for row in rows for v in row):
        raise ValueError("matrix must be a finite 4x4 or 3x3 array")
    return rows


def _matrix_floats(matrix: Any) -> Rotation:
    """The rotation of a camera matrix with unit columns, in the same operations (so to the bit) as
    numpy's ``r / |r|.max(axis=0)`` then ``/ np.linalg.norm(axis=0)``."""
    m = _matrix_rows(matrix)
    cols = []
    for j in range(3):
        c0, c1, c2 = m[0][j], m[1][j], m[2][j]
        big = max(abs(c0), abs(c1), abs(c2))
        if big == 0:
            raise ValueError("matrix has a degenerate rotation")
        c0, c1, c2 = c0 / big, c1 / big, c2 / big  # scale-free first: huge entries must not overflow
        n = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        if n < 1e-12 or not math.isfinite(n):
            raise ValueError("matrix has a degenerate rotation")
        cols.append((c0 / n, c1 / n, c2 / n))  # remove scale
    (a0, a1, a2), (b0, b1, b2), (e0, e1, e2) = cols
    return (a0, b0, e0, a1, b1, e1, a2, b2, e2)


def matrix_rotation(matrix: Any) -> np.ndarray:
    """The rotation of a 4x4 (or 3x3) camera matrix with its scale removed (unit columns); finite but
    huge or tiny entries are fine. ValueError for a non-finite matrix or a zero column."""
    return np.array(_matrix_floats(matrix)).reshape(3, 3)


def rotation_floats(direction: Any = None, matrix: Any = None, up: Any = None) -> Rotation:
    """:func:`camera_rotation` as nine floats (row-major): what the per-frame lookup works with."""
    if (direction is None) == (matrix is None):
        raise ValueError("give exactly one of direction or matrix")
    if matrix is not None:
        return _matrix_floats(matrix)
    return _look_floats(direction, up)


def camera_rotation(direction: Any = None, matrix: Any = None, up: Any = None) -> np.ndarray:
    """3x3 camera-to-world rotation from Blender's 4x4 (or 3x3) ``matrix_world``
    (:func:`matrix_rotation`) or from a view ``direction`` with ``up`` (:func:`look_rotation`)."""
    return np.array(rotation_floats(direction, matrix, up)).reshape(3, 3)


def unit_axes(matrix: Any) -> np.ndarray:
    """A copy of a 4x4 camera matrix with unit-length rotation columns (a camera's scale means nothing,
    and huge but finite entries must not overflow later arithmetic)."""
    m = np.array(matrix, dtype=np.float64)
    m[:3, :3] = matrix_rotation(m)
    return m


def look_matrix(position: Any, direction: Any, up: Any = None) -> np.ndarray:
    """4x4 world matrix of a camera at ``position`` looking along ``direction`` (see
    :func:`look_rotation`)."""
    m = np.eye(4)
    m[:3, :3] = look_rotation(direction, up)
    m[:3, 3] = np.asarray(position, dtype=np.float64).reshape(3)
    return m


def quaternion_matrix(position: Any, quaternion: Any) -> np.ndarray:
    """4x4 world matrix from a position and a rotation quaternion (w, x, y, z: Blender's order; any
    non-zero length)."""
    q = np.asarray(quaternion, dtype=np.float64).reshape(4)
    big = float(np.abs(q).max())
    if big == 0.0:
        raise ValueError("rotation_quaternion must be non-zero")
    q = q / big
    w, x, y, z = q / np.linalg.norm(q)
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, np.asarray(position, dtype=np.float64).reshape(3)
    return m


def forward_of(matrix: Any) -> np.ndarray:
    """Unit view direction of a camera matrix (its local -Z in world space)."""
    f = -np.asarray(matrix, dtype=np.float64)[:3, 2]
    return f / np.linalg.norm(f)


def view_up(forward: Any) -> np.ndarray:
    """Up vector for rendering a sample view: world +Z, or +Y when looking (nearly) along Z."""
    f = np.asarray(forward, dtype=np.float64)
    f = f / np.linalg.norm(f)
    return np.array([0.0, 1.0, 0.0]) if abs(f[2]) > 0.95 else np.array([0.0, 0.0, 1.0])


def face_of(direction: Any) -> int:
    """View-cube face (index into :data:`VIEW_NAMES`) whose cone contains ``direction``."""
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(d)) or not np.any(d):
        raise ValueError("direction must be a finite non-zero 3-vector")
    return SIGNED_TO_VIEW[int(np.concatenate((d, -d)).argmax())]


def check_fov(vfov: Any, name: str = "fov") -> float:
    """A vertical field of view in radians, in [VFOV_MIN, VFOV_MAX)."""
    v = float(vfov)
    if not (math.isfinite(v) and VFOV_MIN <= v < VFOV_MAX):
        raise ValueError(f"{name} must be in [{VFOV_MIN}, {VFOV_MAX}) radians, got {vfov!r}")
    return v


def check_aspect(aspect: Any) -> float:
    """An image aspect (width / height), within 1/MAX_ASPECT .. MAX_ASPECT."""
    a = float(aspect)
    if not (math.isfinite(a) and 1.0 / MAX_ASPECT <= a <= MAX_ASPECT):
        raise ValueError(f"aspect must be within 1/{MAX_ASPECT:g} and {MAX_ASPECT:g}, got {aspect!r}")
    return a


def check_resolution(width: Any, height: Any) -> tuple[int, int]:
    """``(width, height)`` as ints within 1..MAX_RESOLUTION and an aspect within the limits."""
    w, h = int(width), int(height)
    if (w, h) != (width, height) or not (0 < w <= MAX_RESOLUTION and 0 < h <= MAX_RESOLUTION):
        raise ValueError(f"resolution must be two integers in 1..{MAX_RESOLUTION}, got {(width, height)!r}")
    if not 1.0 / MAX_ASPECT <= w / h <= MAX_ASPECT:
        raise ValueError(f"resolution {w}x{h}: the aspect ratio must be within 1:{MAX_ASPECT:g} and "
                         f"{MAX_ASPECT:g}:1")
    return w, h


def check_position(position: Any, name: str = "position") -> tuple[float, float, float]:
    """A camera position: three finite floats within +-MAX_COORDINATE."""
    p = vec3(position, name)
    if max(abs(p[0]), abs(p[1]), abs(p[2])) > MAX_COORDINATE:
        raise ValueError(f"{name} coordinates must be within +-{MAX_COORDINATE:g} m")
    return p


def check_axes(matrix: Any, name: str = "matrix_world") -> np.ndarray:
    """The rotation of a camera matrix with unit columns (:func:`matrix_rotation`), or ValueError when
    its axes span less than MIN_AXES_VOLUME: (nearly) parallel or zero axes give no orientation."""
    try:
        axes = matrix_rotation(matrix)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    if abs(float(np.linalg.det(axes))) < MIN_AXES_VOLUME:
        raise ValueError(f"{name} axes are (nearly) parallel: the matrix must be invertible")
    return axes


def check_affine(rows: Any, name: str) -> None:
    """ValueError unless ``rows`` is an affine 4x4 matrix (last row 0, 0, 0, 1) whose axes pass
    :func:`check_axes` (only their directions matter: huge or tiny but finite entries are fine)."""
    if tuple(rows[3]) != (0.0, 0.0, 0.0, 1.0):
        raise ValueError(f"{name} must be an affine 4x4 matrix with last row [0, 0, 0, 1]")
    check_axes(rows, name)


def normalised_camera_matrix(matrix: Any, name: str = "matrix_world") -> np.ndarray:
    """A camera world matrix checked against the limits (:func:`check_affine`, :func:`check_position`)
    with unit axes, ready for the simulator; ValueError naming the problem otherwise."""
    m = np.array(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"{name} must be 4x4, got shape {m.shape}")
    check_affine(m.tolist(), name)
    check_position(m[:3, 3], f"{name} position")
    m[:3, :3] = matrix_rotation(m)
    return m


def frustum_rays(vfov: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame directions (3, N) of an N = 8 x 8 grid of rays over the image, with the solid angle
    each covers (pixel area on the image plane times cos^3): the frustum sample of :func:`frustum_face`."""
    n = FRUSTUM_SAMPLES
    th = math.tan(vfov / 2)
    v = (np.arange(n) + 0.5) / n * 2 - 1
    uu, vv = np.meshgrid(v * th * aspect, v * th)
    # camera frame: x right, y up, looking down -z; weight = pixel solid angle on the image plane
    d = np.stack([uu.ravel(), vv.ravel(), -np.ones(n * n)])
    w = 1.0 / np.linalg.norm(d, axis=0) ** 3
    return np.ascontiguousarray(d), w


def frustum_face(rotation: np.ndarray, rays: np.ndarray, weights: np.ndarray) -> int:
    """View-cube face that receives the largest (solid-angle weighted) part of a camera's frustum: the
    view cube is a cube map around the camera, and a frustum ray lands on the face of its largest
    direction component. One matrix product over the 64 rays: in plain Python this costs more (a
    corner-ray shortcut plus an exact two-face split measured 12.6 us against numpy's 7.3 us, and a
    third face is in view for half of all random poses)."""
    d = np.asarray(rotation) @ rays  # (3, N) world directions
    # scores in the order +X, +Y, +Z, -X, -Y, -Z; the largest is the face a ray lands on
    face = np.concatenate((d, -d)).argmax(axis=0)
    return SIGNED_TO_VIEW[int(np.bincount(face, weights=weights, minlength=6).argmax())]


def vertical_fov(angle_x: float, angle_y: float, sensor_fit: str, width: int, height: int,
                 pixel_aspect_x: float = 1.0, pixel_aspect_y: float = 1.0) -> float:
    """Vertical field of view (radians) of a perspective Blender camera for a render size.

    ``angle_x`` / ``angle_y`` are the camera's own lens angles over the sensor width / height (Blender's
    ``Camera.angle_x`` / ``angle_y``: the lens and sensor converted once, by Blender). Follows Blender's
    sensor-fit rule: AUTO fits the sensor width to the larger image side, HORIZONTAL fits the width to
    the image width, VERTICAL fits the sensor height to the image height.
    """
    for name, angle in (("angle_x", angle_x), ("angle_y", angle_y)):
        if not (math.isfinite(angle) and 0.0 < angle < math.pi):
            raise ValueError(f"{name} must be a lens angle in (0, pi) radians, got {angle}")
    if width <= 0 or height <= 0:
        raise ValueError(f"resolution must be positive, got {width}x{height}")
    shown_w, shown_h = width * pixel_aspect_x, height * pixel_aspect_y  # the displayed image's shape
    if sensor_fit == "VERTICAL":
        return float(angle_y)
    if sensor_fit not in ("AUTO", "HORIZONTAL"):
        raise ValueError(f"unknown sensor_fit {sensor_fit!r}")
    if sensor_fit == "HORIZONTAL" or shown_w >= shown_h:
        return 2.0 * math.atan(math.tan(angle_x / 2.0) * shown_h / shown_w)
    return float(angle_x)  # AUTO, portrait: the sensor width spans the image height


def camera_lens_from_viewport(viewport_lens_mm: float, sensor_width_mm: float) -> float:
    """Lens of a camera with ``sensor_width_mm`` that frames like the viewport (whose sensor is 72 mm)."""
    if viewport_lens_mm <= 0 or sensor_width_mm <= 0:
        raise ValueError("lens and sensor width must be positive")
    return viewport_lens_mm * sensor_width_mm / VIEWPORT_SENSOR_MM


def projection_window(projection: Any, width: int, height: int) -> tuple[float, int, int, int, int]:
    """A perspective projection as a pinhole camera that renders a window of a centred frame.

    ``projection`` is an OpenGL-style 4x4 matrix, rows as Blender's ``mathutils`` indexes them (a 3D
    view's ``window_matrix``, ``Object.calc_matrix_camera``). Its frustum may be off-centre (camera lens
    shift, a panned camera view); the pinhole camera is centred, so the image is the ``width`` x
    ``height`` window at (``crop_x``, ``crop_y``) from the top left of a ``full_width`` x ``full_height``
    centred frame of the same pixel density. Returns ``(vfov, full_width, full_height, crop_x,
    crop_y)``; ValueError for orthographic or malformed projections. Assumes square pixels.
    """
    p = [[float(projection[i][j]) for j in range(4)] for i in range(4)]
    if not all(math.isfinite(v) for row in p for v in row):
        raise ValueError("projection must be finite")
    if abs(p[3][2] + 1.0) > 1e-6 or abs(p[3][3]) > 1e-6:
        raise ValueError("only perspective projections can be traced (orthographic views cannot)")
    if width <= 0 or height <= 0:
        raise ValueError(f"resolution must be positive, got {width}x{height}")
    sx, sy, a, b = p[0][0], p[1][1], p[0][2], p[1][2]
    if sx <= 0 or sy <= 0:
        raise ValueError("projection must have positive focal terms")
    # NDC x = sx * tan_x - a over the image, so tan_x spans (a - 1, a + 1) / sx (likewise y with b).
    full_w = max(width, round(width * (1.0 + abs(a))))
    full_h = max(height, round(height * (1.0 + abs(b))))
    crop_x = min(full_w - width, max(0, round(width * (a + abs(a)) / 2.0)))
    crop_y = min(full_h - height, max(0, round(height * (abs(b) - b) / 2.0)))
    vfov = 2.0 * math.atan(full_h / (sy * height))
    return check_fov(vfov, "vertical fov of the projection"), full_w, full_h, crop_x, crop_y
