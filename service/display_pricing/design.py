"""One camera's sampling design: its blocks, the size measure from auxiliary frames of a few probe
settings, the sample, and the reference over the sampled regions."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from sim_core.image import linear_to_srgb
from sim_core.render import COUNTER_NAMES

from service.display_pricing.config import DisplayPricing, ssim_margin
from service.display_pricing.sampling import (
    CameraDesign,
    block_of,
    inclusion_probabilities,
    sample_start,
    serpentine,
    systematic_sample,
)
from service.display_pricing.tracing import Renderer
from service.evaluation import CameraSpec
from service.metrics import UNIFORM_WIN, ssim_map
from service.params import Indices, ParameterSpace

_COL = {name: i for i, name in enumerate(COUNTER_NAMES)}


def display_cameras(camera: CameraSpec, pricing: DisplayPricing) -> tuple[Any, Any]:
    """The display camera and the auxiliary frames' (1/``aux_divisor`` of its size a side)."""
    aw = max(8, round(camera.width / pricing.aux_divisor))
    ah = max(8, round(camera.height / pricing.aux_divisor))
    aux = dataclasses.replace(camera, width=aw, height=ah)
    return camera.to_camera(), aux.to_camera()


def aux_measure(renderer: Renderer, aux_cam: Any, settings: Any, aux_reference: np.ndarray, d: CameraDesign
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """Per-block auxiliary error sums (N,), counters (N, C) and histograms (N, 25) of one setting."""
    r = renderer.aux_frame(aux_cam, settings)
    n = d.nbx * d.nby
    ah, aw = aux_reference.shape[:2]
    # uniform window: a map of where they differ
    e = 1.0 - ssim_map(aux_reference, linear_to_srgb(r.image))
    p = UNIFORM_WIN // 2
    yy, xx = np.mgrid[p:ah - p, p:aw - p]
    owner = block_of(xx.ravel() + 0.5, yy.ravel() + 0.5, d.W / aw, d.H / ah, d.B, d.nbx, d.nby)
    x_err = np.bincount(owner, weights=np.maximum(e.ravel(), 0.0), minlength=n)
    return (x_err, *_counter_blocks(r, d), r)


def probes(space: ParameterSpace) -> list[Indices]:
    """The space's cheapest setting and two on the way to the best (the paper's Min, Mid-Min and
    Max-Mid presets): where cheap settings err, for the size measure."""
    lo, hi = space.min_quality_indices(), space.max_quality_indices()
    return list(dict.fromkeys(tuple(round(a + f * (b - a)) for a, b in zip(lo, hi, strict=True))
                              for f in (0.0, 0.25, 0.75)))


def build_design(renderer: Renderer, camera: CameraSpec, space: ParameterSpace, pricing: DisplayPricing,
                 metric: str) -> tuple[CameraDesign, dict[Indices, tuple]]:
    """Blocks, size measure, sample and the reference over the sampled regions (with the auxiliary
    measures of the probes and the reference, which the caller may reuse)."""
    W, H = camera.width, camera.height
    B = pricing.block_for(W, H)
    nbx, nby = -(-W // B), -(-H // B)
    pad = ssim_margin(metric)
    _full_cam, aux_cam = display_cameras(camera, pricing)
    mq = space.max_quality_indices()
    ref_settings = space.to_settings(mq)
    aux_ref = renderer.aux_frame(aux_cam, ref_settings)
    aux_reference = linear_to_srgb(aux_ref.image)
    shell = CameraDesign(W, H, B, nbx, nby, pad, (aux_cam.width, aux_cam.height), aux_reference,
                         np.zeros(0), np.zeros(0, np.int64), {}, np.zeros(0), 0, {})
    n = nbx * nby
    measures: dict[Indices, tuple] = {}
    ref_cnt = _counter_blocks(aux_ref, shell)[0][:, _COL["rays_total"]]
    err = np.zeros(n)
    for probe in probes(space):
        if probe == mq:
            continue
        m = aux_measure(renderer, aux_cam, space.to_settings(probe), aux_reference, shell)
        measures[probe] = m
        if m[0].sum() > 0:
            err += m[0] / m[0].sum()
    size = 0.2 / n + 0.2 * (ref_cnt / ref_cnt.sum() if ref_cnt.sum() > 0 else 1.0 / n)
    size = size + (0.6 * err / err.sum() if err.sum() > 0 else 0.6 / n)
    pi = inclusion_probabilities(size, pricing.fraction * n)
    sampled = systematic_sample(pi, serpentine(nbx, nby), sample_start(pricing.seed, camera,
                                                                         pricing.key(metric)))
    counts = np.zeros(n)
    for b in range(n):
        bx, by = b % nbx, b // nbx
        cw = max(0, min((bx + 1) * B, W - pad) - max(bx * B, pad))
        ch = max(0, min((by + 1) * B, H - pad) - max(by * B, pad))
        counts[b] = cw * ch
    regions = {}
    for b in sampled.tolist():
        bx, by = b % nbx, b // nbx
        regions[b] = (max(0, bx * B - pad), max(0, by * B - pad), min(W, (bx + 1) * B + pad),
                      min(H, (by + 1) * B + pad))
    d = dataclasses.replace(shell, pi=pi, sampled=sampled, regions=regions, counts=counts,
                            interior=int(max(0, W - 2 * pad) * max(0, H - 2 * pad)))
    measures[mq] = (np.zeros(n), *_counter_blocks(aux_ref, d), aux_ref)
    return d, measures


def _counter_blocks(result: Any, d: CameraDesign) -> tuple[np.ndarray, np.ndarray]:
    """Per-block sums of a render's per-tile counters (N, C) and histograms (N, 25)."""
    tb = _tile_blocks(result, (d.W, d.H), d.B, d.nbx, d.nby)
    cnt = np.zeros((d.nbx * d.nby, len(COUNTER_NAMES)))
    np.add.at(cnt, tb, result.tile_counters.astype(np.float64))
    hist = np.zeros((d.nbx * d.nby, 25))
    np.add.at(hist, tb, result.tile_histograms.astype(np.float64))
    return cnt, hist


def _tile_blocks(result: Any, display: tuple[int, int], block: int, nbx: int, nby: int) -> np.ndarray:
    """Block of every tile of a render (by the tile's centre)."""
    w, h = result.render_resolution
    t = result.tile_stats
    cx = np.asarray([s["x0"] + 0.5 * s["width"] for s in t], dtype=np.float64)
    cy = np.asarray([s["y0"] + 0.5 * s["height"] for s in t], dtype=np.float64)
    return block_of(cx, cy, display[0] / w, display[1] / h, block, nbx, nby)
