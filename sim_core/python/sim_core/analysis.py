"""Model only what a scene needs: which effects a scene exercises, and which settings cannot matter.

``analyze(scene)`` reads the scene (materials, lights, environment) and lists the effects it can exercise.
``inert_parameters(scene, space)`` goes further and *verifies by rendering*: a parameter is inert for a
scene when no candidate value changes the image or any activity counter (so neither error nor power can
change) at low resolution, from every base setting tried. The search then leaves it out. The analysis only
supplies the human-readable reason; the decision is always the renders'.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .camera import Camera
from .render import render
from .settings import RenderSettings

__all__ = ["SceneAnalysis", "analyze", "inert_parameters"]


@dataclass(frozen=True)
class SceneAnalysis:
    """Effects a scene can exercise (what the energy model may have to price for it)."""

    triangles: int
    lights: int
    shadow_bits: int  # one per light (the similarity test's shadow bits)
    reflection: bool  # some material traces mirror/glossy reflection rays
    glossy: bool  # some reflective material is rough (cone-filtered environment lookups)
    refraction: bool  # some material transmits (refraction rays)
    emission: bool
    soft_shadows: bool  # some light has a radius or an area (shadow samples > 1 matter)
    environment_map: bool  # an equirectangular map (environment filtering can matter)
    effects: tuple[str, ...]
    area_lights: bool = False  # some light is an area light (area-light evaluations)
    textures: bool = False  # some material samples a base-colour texture (texture fetches, texture cache)
    alpha_cutouts: bool = False  # some material can be cut out by its alpha (alpha tests, continuation rays)

    def possible_counters(self) -> set[str]:
        """Counters that can be non-zero for this scene; the rest stay 0 in every render."""
        always = {"rays_primary", "rays_total", "bvh_node_visits", "triangle_tests", "shading_evals",
                  "raygen_evals", "similarity_checks", "interpolations", "reprojections",
                  "tile_buffer_reads", "tile_buffer_writes", "framebuffer_bytes", "gbuffer_prefetch_bytes",
                  "cache_accesses", "cache_misses", "dram_bytes_read", "closest_hit_comparisons",
                  "env_lookups", "samples_traced", "samples_interpolated", "samples_reused", "pixels",
                  "rays_ao", "resolve_taps", "resolve_bytes", "ambient_filter_taps"}
        if self.lights:
            always.add("rays_shadow")
        if self.reflection:
            always.add("rays_reflection")
        if self.glossy:
            always.add("rays_glossy")
        if self.refraction:
            always.add("rays_refraction")
        if self.glossy and self.environment_map:
            always.add("env_filtered_lookups")
        if self.environment_map:
            always.add("env_sh_evals")
        if self.area_lights:
            always.add("area_light_evals")
        if self.textures:
            always |= {"texture_fetches", "texel_reads", "texture_cache_misses", "texture_dram_bytes"}
        if self.alpha_cutouts:
            always |= {"alpha_tests", "rays_alpha"}
        return always


def analyze(scene: Any) -> SceneAnalysis:
    """List the effects ``scene`` (a ``sim_core.Scene``) can exercise, from its materials and lights."""
    mats = list(getattr(scene, "materials", []) or [])
    lights = list(getattr(scene, "lights", []) or [])
    stats = dict(getattr(scene, "stats", {}) or {})
    reflection = any(m.metallic > 0.0 or m.roughness < 0.5 for m in mats)
    glossy = any((m.metallic > 0.0 or m.roughness < 0.5) and m.roughness > 0.0 for m in mats)
    refraction = any(m.transmission > 0.0 for m in mats)
    emission = any(max(m.emission) > 0.0 for m in mats)
    # The environment map's suns light the scene as soft sun lights (after the scene's own lights).
    sun_count = int(stats.get("environment_lights", 0))
    soft = any(light.radius > 0.0 or light.kind == "area" for light in lights) or sun_count > 0
    effects = tuple(stats.get("effects", ()))
    env_map = "environment_map" in effects
    area = any(light.kind == "area" for light in lights)
    textures = "textures" in effects
    cutouts = "alpha_cutouts" in effects
    flags = ((bool(lights) or sun_count > 0, "shadows"), (soft, "soft_shadows"), (reflection, "reflection"),
             (glossy, "glossy_reflection"), (refraction, "refraction"), (emission, "emission"),
             (env_map, "environment_map"), (area, "area_lights"), (textures, "textures"),
             (cutouts, "alpha_cutouts"))
    eff = [name for on, name in flags if on]
    return SceneAnalysis(
        triangles=int(stats.get("triangles", 0)), lights=len(lights) + sun_count,
        shadow_bits=len(lights) + sun_count,
        reflection=reflection, glossy=glossy, refraction=refraction, emission=emission, soft_shadows=soft,
        environment_map=env_map, effects=tuple(eff), area_lights=area, textures=textures,
        alpha_cutouts=cutouts,
    )


def _default_camera(scene: Any, width: int, height: int) -> Any:
    cams = list(getattr(scene, "cameras", []) or [])
    if cams:
        c = cams[0]
        return Camera.from_blender(np.asarray(c.matrix_world, dtype=np.float64), float(c.vfov), width, height)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
    centre, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    eye = centre + np.array([0.35, -0.9, 0.45]) * max(diag, 1e-3)
    return Camera.look_at(eye, centre, (0.0, 0.0, 1.0), 0.7, width, height)


def _reason(name: str, a: SceneAnalysis) -> str:
    hints = {
        "max_depth": (not a.reflection and not a.refraction,
                      "the scene has no reflective or refractive material, so no secondary rays exist"),
        "env_filter": (not (a.glossy and a.environment_map),
                       "no glossy material reflects an environment map"),
        "shadow_samples": (a.lights == 0 or not a.soft_shadows,
                           "no light" if a.lights == 0 else "every light is a point (hard shadows)"),
    }
    base = "no candidate value changed the image or any activity counter"
    hint = hints.get(name)
    return f"{base} ({hint[1]})" if hint and hint[0] else base


def _contexts(name: str, space: Mapping[str, Sequence[Any]], bases: Sequence[Any]) -> list[Any]:
    """Base settings to vary ``name`` from: every base, and every base with one other parameter of the
    space set to each of its candidates (so interactions such as threshold x adaptive mode count)."""
    out, seen = [], set()
    for base in bases:
        cands = [base]
        for other, vals in space.items():
            if other == name:
                continue
            for v in vals:
                try:
                    cands.append(dataclasses.replace(base, **{other: v}))
                except ValueError:
                    continue  # an invalid combination is not a context the search can reach
        for c in cands:
            if repr(c) not in seen:
                seen.add(repr(c))
                out.append(c)
    return out


def inert_parameters(scene: Any, space: Mapping[str, Sequence[Any]], camera: Any = None, *,
                     resolution: tuple[int, int] = (48, 32), bases: Sequence[Any] | None = None,
                     threads: int | None = None) -> dict[str, str]:
    """Settings of ``space`` that cannot change ``scene``'s image or power, with the reason.

    ``space`` maps ``RenderSettings`` field names to candidate values. A parameter is varied over its
    candidates from every context: each base setting (default: ``RenderSettings.max_quality()`` and
    ``RenderSettings()``) and each base with one other parameter of the space set to one of its candidates
    (so a similarity threshold is tried under an adaptive mode when the space offers one). The scene is
    rendered at ``resolution`` (the camera is re-made at that size); the parameter is inert when, in every
    context, all its values give the same image (bit for bit) and the same counters. ``camera`` defaults
    to the scene's first camera or one framing its bounds.
    """
    fields = {f.name for f in dataclasses.fields(RenderSettings)}
    for name, values in space.items():
        if name not in fields:
            raise ValueError(f"unknown RenderSettings field {name!r}")
        if isinstance(values, (str, bytes)) or len(values) == 0:
            raise ValueError(f"space[{name!r}] must be a non-empty sequence of values")
    w, h = resolution
    if w < 4 or h < 4:
        raise ValueError("resolution must be at least 4x4")
    if camera is None:
        cam = _default_camera(scene, w, h)
    else:
        cam = camera.with_resolution(w, h) if hasattr(camera, "with_resolution") else camera
    base_list = list(bases) if bases is not None else [RenderSettings.max_quality(), RenderSettings()]
    analysis = analyze(scene)
    cache: dict[Any, tuple[np.ndarray, dict[str, int]]] = {}

    def run(settings: Any) -> tuple[np.ndarray, dict[str, int]]:
        key = repr(settings)
        if key not in cache:
            r = render(scene, cam, settings, threads=threads)
            cache[key] = (np.asarray(r.image), dict(r.counters))
        return cache[key]

    inert: dict[str, str] = {}
    for name, values in space.items():
        if len(values) < 2:
            inert[name] = "a single candidate value: nothing to choose"
            continue
        same = True
        for base in _contexts(name, space, base_list):
            ref_img, ref_cnt = None, None
            for v in values:
                try:
                    settings = dataclasses.replace(base, **{name: v})
                except ValueError:
                    continue
                img, cnt = run(settings)
                if ref_img is None:
                    ref_img, ref_cnt = img, cnt
                elif img.shape != ref_img.shape or not np.array_equal(img, ref_img) or cnt != ref_cnt:
                    same = False
                    break
            if not same:
                break
        if same:
            inert[name] = _reason(name, analysis)
    return inert
