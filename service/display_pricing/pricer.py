"""The driver the octree builder calls: display-resolution pricing through the evaluation cache and
the executor, one task per camera."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from service.display_pricing.camera import price_camera
from service.display_pricing.config import DisplayPricing
from service.display_pricing.references import ReferenceStore
from service.eval_cache import CacheKey, Evaluation
from service.evaluation import PIPELINE_VERSION, CameraSpec, Evaluator, SceneHandle, space_fingerprint
from service.params import Indices, ParameterSpace


@dataclass(frozen=True)
class _TaskContext:
    """What every pricing task of a batch shares (sent once per worker and batch)."""

    scene: SceneHandle
    space: ParameterSpace
    profile: str
    fps: float
    metric: str
    pricing: DisplayPricing
    threads: int | None
    references: str | None  # the build's reference directory (ReferenceStore), if any


def _price_task(ctx: _TaskContext, item: tuple[CameraSpec, list[Indices]]) -> list[Evaluation]:
    camera, settings = item
    return price_camera(ctx.scene.get(), camera, settings, ctx.space, profile=ctx.profile, fps=ctx.fps,
                        metric=ctx.metric, pricing=ctx.pricing, threads=ctx.threads,
                        scene_hash=ctx.scene.content_hash,
                        references=None if ctx.references is None else ReferenceStore(ctx.references))


class DisplayPricer:
    """Prices (display-resolution camera, settings) at display resolution for an :class:`Evaluator`'s
    scene, space, profile, frame rate and metric, through its evaluation cache and executor: one task
    per camera (its reference is traced once for all its settings), cached per setting under a key
    that names the display resolution and the estimator. With ``references`` (an existing directory the
    workers see, one build's), a camera priced again in a later call reads its reference from there
    instead of rendering it again (:class:`ReferenceStore`)."""

    def __init__(self, evaluator: Evaluator, pricing: DisplayPricing, references: str | Path | None = None
                 ) -> None:
        self.ev = evaluator
        self.pricing = pricing
        ctx = evaluator.ctx
        self.ctx = _TaskContext(evaluator.scene, evaluator.space, ctx.profile, ctx.fps, ctx.metric, pricing,
                                ctx.threads, None if references is None else str(references))
        self.metric_key = (f"{ctx.metric}:{PIPELINE_VERSION}:{space_fingerprint(evaluator.space)}:"
                           f"display={pricing.key(ctx.metric)}")
        self.evaluations = 0  # settings actually priced, in calls to price that ended (or were cancelled)
        self.cameras = 0  # camera tasks run

    def _key(self, camera: CameraSpec) -> CacheKey:
        return CacheKey(self.ev.scene.content_hash, camera.key(), self.metric_key, self.ev.profile_key,
                        camera.width, camera.height, self.ctx.fps)

    def uncached(self, requests: Sequence[tuple[CameraSpec, Sequence[Indices]]]) -> int:
        """How many settings :meth:`price` would render for ``requests`` now: those the evaluation cache
        does not hold, each camera's counted once (a rerun or resumed job knows its work before it
        starts, where a pace taken over cached batches would promise minutes for an hour)."""
        space = self.ev.space
        wanted: dict[str, tuple[CameraSpec, set[int]]] = {}
        for cam, xs in requests:
            wanted.setdefault(cam.key(), (cam, set()))[1].update(space.pack(x) for x in xs)
        return sum(self.ev.cache.count_missing(self._key(cam), sorted(packs))
                   for cam, packs in wanted.values())

    def price(self, requests: Sequence[tuple[CameraSpec, Sequence[Indices]]],
              on_progress: Callable[[int, int], None] | None = None) -> list[list[Evaluation]]:
        """Evaluations of every request's settings, in order; cached ones are not priced again.
        ``on_progress(rendered, to_render)``: settings rendered so far of those the cache did not hold,
        as camera tasks finish (a batch of cameras at display resolution can take many minutes)."""
        space = self.ev.space
        reqs = [(cam, [tuple(int(i) for i in x) for x in xs]) for cam, xs in requests]
        found: dict[tuple[str, int], Evaluation] = {}
        todo: dict[str, tuple[CameraSpec, list[Indices]]] = {}
        for cam, xs in reqs:
            packs = {space.pack(x): x for x in xs}
            hit = self.ev.cache.get_many(self._key(cam), list(packs))
            self.ev.cache_hits += len(hit)
            for p, e in hit.items():
                found[(cam.key(), p)] = e
            missing = [x for p, x in packs.items() if p not in hit and (cam.key(), p) not in found]
            if missing:
                entry = todo.setdefault(cam.key(), (cam, []))
                entry[1].extend(x for x in missing if x not in entry[1])
        if todo:
            items = list(todo.values())
            to_render = sum(len(xs) for _, xs in items)
            rendered = cameras = 0

            def done(finished: range, results: Sequence[list[Evaluation]]) -> None:
                # Cached as each camera finishes, before progress is reported: a cancel (raised from
                # on_progress) or a failure later in the batch loses none of the finished cameras.
                nonlocal rendered, cameras
                for i, evs in zip(finished, results, strict=True):
                    cam, xs = items[i]
                    pairs = [(space.pack(x), e) for x, e in zip(xs, evs, strict=True)]
                    self.ev.cache.put_many(self._key(cam), pairs)
                    found.update(((cam.key(), p), e) for p, e in pairs)
                    rendered, cameras = rendered + len(pairs), cameras + 1
                if on_progress is not None:
                    on_progress(rendered, to_render)

            try:
                # one task a camera (each takes seconds to minutes): reported as it ends, load balanced
                self.ev.executor.map(_price_task, self.ctx, items, on_done=done, chunks=len(items))
            finally:  # the counters move once the call ends (the builder reads them between batches)
                self.cameras += cameras
                self.evaluations += rendered
                self.ev.evaluations += rendered
        return [[found[(cam.key(), space.pack(x))] for x in xs] for cam, xs in reqs]
