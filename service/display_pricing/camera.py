"""Pricing every setting at one camera at display resolution: whole frames, or the tile estimator."""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np

from service.display_pricing.config import DisplayPricing
from service.display_pricing.design import aux_measure, build_design, display_cameras, probes
from service.display_pricing.estimator import estimate
from service.display_pricing.references import ReferenceStore
from service.display_pricing.sampling import CameraDesign
from service.display_pricing.tracing import Renderer, display_patches
from service.eval_cache import Evaluation
from service.evaluation import (  # the evaluator's own error and pricing, so both agree
    CameraSpec,
    _price,
    image_error,
)
from service.lru import LRUCache
from service.metrics import ssim
from service.params import Indices, ParameterSpace

_DESIGNS: LRUCache[tuple[str, ...], tuple[CameraDesign, dict]] = LRUCache(4)


def price_camera(scene: Any, camera: CameraSpec, settings: Sequence[Indices], space: ParameterSpace, *,
                 profile: str, fps: float, metric: str, pricing: DisplayPricing,
                 threads: int | None = None, scene_hash: str | None = None,
                 references: ReferenceStore | None = None) -> list[Evaluation]:
    """Error, power and frame time of every setting at ``camera`` (display resolution), priced as
    ``pricing`` says; the maximum-quality reference is rendered once for all of them, and with
    ``references`` once for every call at this camera (the builder's later pricing rounds)."""
    renderer = Renderer(scene, threads)
    mq = space.max_quality_indices()
    key = (scene_hash or str(scene.content_hash), camera.key(), metric, pricing.key(metric),
           repr(sorted(space.fields_of(mq).items())))
    if pricing.key(metric).startswith("full"):
        return _price_whole_frames(renderer, camera, settings, space, profile=profile, fps=fps, metric=metric,
                                   references=references, key=key)
    key = (*key, repr(probes(space)))
    cached = _DESIGNS.get(key)
    if cached is None and references is not None:
        cached = references.load_design(key)
    if cached is None:
        cached = build_design(renderer, camera, space, pricing, metric)
    _DESIGNS.put(key, cached)
    d, probe_measures = cached
    full_cam, aux_cam = display_cameras(camera, pricing)
    blocks = d.sampled.tolist()
    if d.reference_tiles is None:
        canvas, cnt, hist, owner, size = renderer.windows(full_cam, space.to_settings(mq), blocks, d)
        d.reference.update(display_patches(canvas, size, d, blocks))
        d.reference_tiles = (cnt, hist, owner, size)
        if references is not None:
            references.save_design(key, d, probe_measures)
    gaussian = metric == "ssim_gaussian"
    out = []
    traced_pixels = sum((r[2] - r[0]) * (r[3] - r[1]) for r in d.regions.values())
    for idx in settings:
        idx = tuple(int(i) for i in idx)
        s = space.to_settings(idx)
        if idx == mq:
            cnt, hist, owner, size = d.reference_tiles
            y_err = None
        else:
            canvas, cnt, hist, owner, size = renderer.windows(full_cam, s, blocks, d)
            test = display_patches(canvas, size, d, blocks)
            y_err = np.asarray([d.counts[b] * (1.0 - ssim(d.reference[b], test[b], gaussian_weights=gaussian))
                                if d.counts[b] > 0 else 0.0 for b in blocks])
        aux = probe_measures.get(idx)
        if aux is None:
            aux = aux_measure(renderer, aux_cam, s, d.aux_reference, d)
        error, se_err, counters, histogram, se_rays = estimate(d, y_err, cnt, hist, owner, aux, size)
        est = SimpleNamespace(counters=counters, comparator_histogram=histogram, settings=s)
        power, frame_time, breakdown = _price(est, profile, fps)
        breakdown.update(_labels(camera, size, fraction=traced_pixels / (d.W * d.H)))
        breakdown.update({"display.se_error": se_err, "display.se_rays_rel": se_rays,
                          "display.blocks_sampled": float(len(blocks)),
                          "display.blocks_total": float(d.nbx * d.nby)})
        out.append(Evaluation(error, power, frame_time, breakdown))
    return out


def _price_whole_frames(renderer: Renderer, camera: CameraSpec, settings: Sequence[Indices],
                        space: ParameterSpace, *, profile: str, fps: float, metric: str,
                        references: ReferenceStore | None, key: tuple[str, ...]) -> list[Evaluation]:
    """Every setting and the reference rendered whole at display resolution: exact, and as slow. The
    reference image comes from ``references`` where an earlier call at this camera saved it (unless max
    quality is priced itself, whose render is the reference)."""
    mq = space.max_quality_indices()
    settings = [tuple(int(i) for i in idx) for idx in settings]
    rendered: dict[Indices, Any] = {}
    ref_image = None
    if references is not None and mq not in settings:
        ref_image = references.load_frame(key)
    if ref_image is None:
        rendered[mq] = renderer.frame(camera.to_camera(), space.to_settings(mq))
        ref_image = rendered[mq].image
        if references is not None:
            references.save_frame(key, ref_image)
    out = []
    for idx in settings:
        r = rendered[idx] if idx in rendered else renderer.frame(camera.to_camera(), space.to_settings(idx))
        err = 0.0 if idx == mq else image_error(metric, ref_image, r.image)
        power, frame_time, breakdown = _price(r, profile, fps)
        breakdown.update(_labels(camera, r.render_resolution, fraction=1.0))
        out.append(Evaluation(err, power, frame_time, breakdown))
    return out


def _labels(camera: CameraSpec, size: tuple[int, int], *, fraction: float) -> dict[str, float]:
    return {"display.width": float(camera.width), "display.height": float(camera.height),
            "display.traced_width": float(size[0]), "display.traced_height": float(size[1]),
            "display.pixel_fraction": float(fraction)}
