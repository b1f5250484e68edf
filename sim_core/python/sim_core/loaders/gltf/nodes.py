"""The glTF node hierarchy: local matrices, the depth-first walk of the default scene, and what nodes
carry besides meshes (KHR_lights_punctual lights in Blender's units, perspective cameras, and
EXT_mesh_gpu_instancing instances)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...scene_data import CameraData, Light
from .accessors import read_accessor
from .document import Document

#: glTF (Y-up) to Blender (Z-up) world frame: (x, y, z) -> (x, -z, y).
GLTF_TO_BLENDER = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
#: Luminous efficacy Blender's glTF exporter assumes ('SPEC' mode): lm per W.
LUMENS_PER_WATT = 683.0
#: Light extras key for the emitter size glTF cannot express: radius in metres for point and spot lights,
#: angular radius in radians for sun lights (Blender's shadow_soft_size, and half its sun angle).
LIGHT_RADIUS_EXTRAS_KEY = "render_budget_radius"


def quat_to_matrix(q: list[float]) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0 or not math.isfinite(n):
        raise ValueError(f"node rotation quaternion {q} is invalid")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _local_matrix(node: dict[str, Any]) -> np.ndarray:
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=np.float64)
        if m.shape != (16,):
            raise ValueError(f"node matrix must have 16 numbers, got {m.shape}")
        m = m.reshape(4, 4).T  # glTF stores column-major
    else:
        t = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
        r = quat_to_matrix(node.get("rotation", [0.0, 0.0, 0.0, 1.0]))
        s = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
        if t.shape != (3,) or s.shape != (3,):
            raise ValueError("node translation and scale must have 3 numbers")
        m = np.eye(4)
        m[:3, :3] = r * s[None, :]
        m[:3, 3] = t
    if not np.all(np.isfinite(m)):
        raise ValueError(f"node {node.get('name', '')!r} has a non-finite transform")
    return m


def walk_nodes(doc: Document) -> list[tuple[int, np.ndarray]]:
    """(node index, world matrix in the glTF frame) for every node of the default scene, depth first."""
    gltf = doc.gltf
    nodes = gltf.get("nodes", [])
    scenes = gltf.get("scenes", [])
    if scenes:
        scene_index = int(gltf.get("scene", 0))
        if not 0 <= scene_index < len(scenes):
            raise ValueError(f"{doc.path}: default scene {scene_index} does not exist")
        roots = list(scenes[scene_index].get("nodes", []))
    else:  # no scene: every node that is nobody's child is a root
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    out: list[tuple[int, np.ndarray]] = []
    seen: set[int] = set()
    stack = [(int(r), np.eye(4)) for r in reversed(roots)]
    while stack:
        index, parent = stack.pop()
        if not 0 <= index < len(nodes):
            raise ValueError(f"{doc.path}: node {index} does not exist")
        if index in seen:
            raise ValueError(f"{doc.path}: node {index} appears twice in the hierarchy (cycle or shared)")
        seen.add(index)
        world = parent @ _local_matrix(nodes[index])
        out.append((index, world))
        for child in reversed(nodes[index].get("children", [])):
            stack.append((int(child), world))
    return out


def read_light(doc: Document, index: int, world_b: np.ndarray, name: str) -> Light:
    lights = doc.gltf.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    if not 0 <= index < len(lights):
        raise ValueError(f"{doc.path}: light {index} does not exist")
    src = lights[index]
    gtype = src.get("type")
    kinds = {"point": "POINT", "spot": "SPOT", "directional": "SUN"}
    if gtype not in kinds:
        raise ValueError(f"{doc.path}: light {index} has unknown type {gtype!r}")
    spot = src.get("spot", {})
    extras = src.get("extras") if isinstance(src.get("extras"), dict) else {}
    radius = float(extras.get(LIGHT_RADIUS_EXTRAS_KEY, 0.0))
    intensity = float(src.get("intensity", 1.0)) / LUMENS_PER_WATT  # W/sr (point, spot) or W/m^2 (sun)
    outer = float(spot.get("outerConeAngle", math.pi / 4))
    inner = float(spot.get("innerConeAngle", 0.0))
    blend = float(np.clip(1.0 - inner / outer, 0.0, 1.0)) if outer > 0 else 0.0
    # Lights shine down their local -Z in glTF and in Blender alike; from_blender reads that off world_b.
    return Light.from_blender(
        kinds[gtype],
        world_b,
        intensity if gtype == "directional" else intensity * 4.0 * math.pi,
        tuple(float(c) for c in src.get("color", [1.0, 1.0, 1.0])),
        shadow_soft_size=radius if gtype != "directional" else 0.0,
        angle=2.0 * radius if gtype == "directional" else 0.0,
        spot_size=2.0 * outer,
        spot_blend=blend,
        name=str(src.get("name", name)),
    )


def gpu_instances(doc: Document, ext: dict[str, Any], what: str) -> list[np.ndarray]:
    """EXT_mesh_gpu_instancing: per-instance local matrices (T * R * S) from its attribute accessors."""
    attrs = ext.get("attributes", {})
    if not attrs:
        raise ValueError(f"{doc.path}: {what}: EXT_mesh_gpu_instancing without attributes")
    arrays = {k: read_accessor(doc, int(v)).astype(np.float64) for k, v in attrs.items()
              if k in ("TRANSLATION", "ROTATION", "SCALE")}
    counts = {a.shape[0] for a in arrays.values()}
    if len(counts) != 1:
        raise ValueError(f"{doc.path}: {what}: instance attributes differ in count")
    n = counts.pop()
    t = arrays.get("TRANSLATION", np.zeros((n, 3)))
    r = arrays.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    sc = arrays.get("SCALE", np.ones((n, 3)))
    if t.shape[1] != 3 or r.shape[1] != 4 or sc.shape[1] != 3:
        raise ValueError(f"{doc.path}: {what}: instance attributes have the wrong types")
    out = []
    for k in range(n):
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(list(r[k])) * sc[k][None, :]
        m[:3, 3] = t[k]
        if not np.all(np.isfinite(m)):
            raise ValueError(f"{doc.path}: {what}: instance {k} has a non-finite transform")
        out.append(m)
    return out


def read_camera(doc: Document, index: int, world_b: np.ndarray, name: str) -> CameraData | None:
    """A node's perspective camera (None for an orthographic one, which is not modelled)."""
    cams = doc.gltf.get("cameras", [])
    if not 0 <= index < len(cams):
        raise ValueError(f"{doc.path}: camera {index} does not exist")
    persp = cams[index].get("perspective")
    if persp is None:
        return None
    yfov = float(persp["yfov"])
    aspect = float(persp.get("aspectRatio", 16 / 9))
    if not (0.0 < yfov < math.pi):
        raise ValueError(f"{doc.path}: camera {index} yfov {yfov} outside (0, pi)")
    if not (math.isfinite(aspect) and aspect > 0.0):
        raise ValueError(f"{doc.path}: camera {index} aspectRatio {aspect} must be positive")
    return CameraData(matrix_world=world_b.copy(), vfov=yfov, aspect=aspect, name=name)
