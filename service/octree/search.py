"""The lock-step search scheduler: the Pareto frontiers of many cameras at once, every generation of
every camera sent to the executor as one batch, with progress and cancellation.

Each search is NSGA-II (or exhaustive enumeration when the space is small) seeded from the run seed
and the camera, starting from both ends of the space (the maximum-quality setting, error 0 by
definition, and the cheapest one) plus its warm start. A setting whose frame time misses the run's
target frame rate is infeasible (:func:`service.store.meets_frame_rate`): the searches rank it behind
every setting that keeps up. A search's frontier is drawn from every setting it evaluated (its
archive), in the store's two tiers (:func:`service.store.frontier_tiers`): the front of the settings
that keep up, then the front of those that miss the rate but are more accurate than any that keeps up
(the maximum-quality setting, always evaluated, ends it unless it keeps up).

Ranked behind every real-time setting, the slow region is barely explored by NSGA-II (a handful of
the ~250 settings a camera evaluates), so the slow tier was often the maximum-quality setting alone and
an error budget no real-time setting keeps was kept with Max. After each search that left settings on
both sides of the frame rate, a few deterministic *probes* (:meth:`Search.probes`) between the most
accurate real-time setting and Max are evaluated; those that miss the rate join the archive, so the slow
tier can hold intermediate points. Probes that happen to keep up stay out of the frontier: the meeting
tier, which the warm starts and frontier comparisons read, stays what the search found. They are
returned beside it (:class:`Found`), since they are often the most accurate real-time settings the search
met: on the valley (`desktop`) the sampler one step below Max kept up at error 0.007 in the search's
64x36 images at a camera whose priced frontier went from a slow Max to real-time points at 0.034 and
over (320x180); with them dropped, an unbridged store missed the error budget at six path frames
(bench/RESULTS.md, "The valley's missed frames without bridging"). The display pricing prices them
where the frontier's real-time points stay over error 0.02 (:mod:`.builder`). The scheduler
knows cameras and settings, not corners or views: the sampling strategies (:mod:`.view_cubes`,
:mod:`.path_samples`) decide what to search where.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.evaluation import CameraSpec, Evaluator
from service.nsga import NSGA2, Archive, NSGAConfig, enumerate_space
from service.params import Indices, ParameterSpace
from service.store import frontier_tiers, meets_frame_rate, split_by_rate

#: A frontier: (full index vector, error, power, frame time) of each setting.
Points = list[tuple[Indices, float, float, float]]

#: The most a run's fraction done reads before the run is done (its last step counted, the frontiers
#: still being written): 1 means done.
FRACTION_BEFORE_DONE = 0.99

#: Where the probes' chain from Max towards the most accurate real-time setting stops (fractions of the
#: way, per parameter index).
PROBE_CHAIN = (0.25, 0.5, 0.75)
#: Added to the error a descent step adds before dividing the frame time it saves by it: steps whose
#: error change is below it (a few thousandths of 1 - SSIM at the search's small images) rank by the time
#: they save.
DESCENT_ERROR_FLOOR = 0.001
#: The slow settings a search keeps for the display pricing to try (:meth:`Search.near_deadline`): those
#: whose frame time is at most this multiple of the deadline. The search's frame time is its small
#: image's counters scaled by the pixel ratio, and at 640x360 it ran up to a third slow: the valley's
#: FSAA with 1 shadow ray and AO 4 read 24.1 fps there and ran at 32.6 fps rendered whole
#: (bench/RESULTS.md, "Slow settings near the deadline priced at display resolution").
NEAR_DEADLINE = 1.5


@dataclass(frozen=True)
class Found:
    """One camera's search: its two-tier frontier, the probes that kept up with the frame rate,
    which the frontier leaves out (not dominated-checked against it), and the slow settings near the
    deadline (:meth:`Search.near_deadline`)."""

    points: Points
    kept_up: Points
    near: Points = field(default_factory=list)


class Cancelled(Exception):
    """The optimisation was cancelled through ``should_cancel``."""


@dataclass
class Progress:
    """Where a run stands: views optimised of those planned so far, renders, cache hits, time, and the
    fraction of the whole run done (:meth:`Search.report`: search and display pricing, in search steps;
    never decreasing, 1 only when the run is done)."""

    views_done: int = 0
    views_planned: int = 0
    evaluations: int = 0
    cache_hits: int = 0
    elapsed_s: float = 0.0
    estimate_s: float | None = None
    phase: str = "starting"
    fraction: float = 0.0


def camera_seed(seed: int, camera: CameraSpec) -> int:
    return (int(seed) * 1_000_003 + zlib.crc32(camera.key().encode())) % (2**63)


class Search:
    """Runs searches in lock-step and keeps the run's progress (``state``)."""

    def __init__(self, evaluator: Evaluator, space: ParameterSpace, nsga: NSGAConfig, exhaustive_limit: int,
                 progress: Callable[[Progress], None] | None = None,
                 should_cancel: Callable[[], bool] | None = None, *, descent_steps: int = 0) -> None:
        self.ev = evaluator
        self.descent_steps = int(descent_steps)
        self.descent_evaluated = 0  # settings a descent evaluated (cache hits included), all searches
        self.space = space
        self.nsga = nsga
        self.exhaustive_limit = exhaustive_limit
        self._progress_cb = progress
        self._should_cancel = should_cancel
        self.t0 = time.perf_counter()
        self.steps_done = 0
        self.steps_planned = 0
        self.probes_evaluated = 0  # probe settings evaluated (cache hits included), all searches
        self.state = Progress(phase="root")
        # the phases after the search still to come (not yet in steps_planned), in search renders (at the
        # evaluation size) as far as they are known so far: their time left at the search's own pace per
        # render, and their search steps (a population of renders each) in the fraction done
        self.renders_after: Callable[[], float] | None = None

    # -- bookkeeping --------------------------------------------------------------------------------

    def report(self, phase: str | None = None, remaining_s: float | None = None) -> None:
        """Publish the progress; ``remaining_s``: the time left as the caller measured it (the last
        phase's own pace), instead of the search steps' pace plus what :attr:`renders_after` expects of
        the phases after the search.

        The fraction done is the steps done of those planned, the phases after the search included
        (:attr:`renders_after` while they are not planned yet), so that a last phase as long as the display
        pricing is not a run at 100 %. Steps planned grow as the run learns its work (more views, the
        pricing's own count when it starts): the fraction keeps the highest value it reached, and stays
        at most :data:`FRACTION_BEFORE_DONE` until :meth:`finish`."""
        if phase is not None:
            self.state.phase = phase
        s = self.state
        later = self.renders_after() if self.renders_after is not None else 0.0
        total = self.steps_planned + later / max(1, self.nsga.population)
        if total > 0:
            s.fraction = max(s.fraction, min(FRACTION_BEFORE_DONE, self.steps_done / total))
        s.evaluations = self.ev.evaluations
        s.cache_hits = self.ev.cache_hits
        s.elapsed_s = time.perf_counter() - self.t0
        # time per search step (one generation, or one chunk of an enumeration, of one camera) so far,
        # times the steps still planned: warm-started searches are shorter than full ones
        # (none while every step was answered from the evaluation cache: that pace is no guide to renders)
        s.estimate_s = (s.elapsed_s / self.steps_done * max(self.steps_planned - self.steps_done, 0)
                        if self.steps_done and s.evaluations > 0 else None)
        if remaining_s is not None:
            s.estimate_s = max(0.0, float(remaining_s))
        elif s.estimate_s is not None:  # (None above when the search was answered by the cache)
            s.estimate_s += later * s.elapsed_s / s.evaluations
        if self._progress_cb is not None:
            self._progress_cb(Progress(**vars(s)))

    def finish(self) -> None:
        """Publish the run as done (fraction 1)."""
        self.state.fraction = 1.0
        self.report("done")

    def check_cancel(self) -> None:
        if self._should_cancel is not None and self._should_cancel():
            self.report("cancelled")
            raise Cancelled("optimisation cancelled")

    def evaluate(self, requests: Sequence[tuple[CameraSpec, Indices]]) -> list[Any]:
        """Error and power of (camera, settings) requests, as one batch."""
        return self.ev.evaluate(requests)

    @property
    def exhaustive(self) -> bool:
        return self.space.size <= self.exhaustive_limit

    def steps(self, n_jobs: int, generations: int | None = None) -> int:
        """Steps of ``n_jobs`` searches run together: chunks of the enumeration, or NSGA-II generations
        plus one step of probes each (at most a generation's worth of settings)."""
        if self.exhaustive:
            n = math.prod(self.space.free_n_values)
            return n_jobs * -(-n // max(1, 256 // max(1, n_jobs)))
        return n_jobs * ((generations or self.nsga.generations) + 1 + self.descent_steps)

    # -- the searches -------------------------------------------------------------------------------

    def run(self, cameras: Sequence[CameraSpec], warm: Sequence[list[Indices]], phase: str,
            generations: int | None = None, planned: bool = False) -> list[Found]:
        """The frontier of each camera (warm-started from ``warm``) and its probes that kept up, all
        searches in lockstep;
        ``generations`` overrides the configured number (short searches from a good warm start);
        ``planned``: their steps were already counted in the progress estimate."""
        if not cameras:
            return []
        steps_before = self.steps_done
        stage_steps = self.steps(len(cameras), generations)
        if not planned:
            self.steps_planned += stage_steps
        times: list[dict[Indices, float]] = [{} for _ in cameras]  # frame time of every evaluated setting
        kept_up: list[Points] = [[] for _ in cameras]
        if self.exhaustive:
            archives = self._enumerate(cameras, phase, times)
        else:
            archives = self._nsga(cameras, warm, phase, generations, times)
            kept_up = self._probe(cameras, archives, times, phase)
            if self.descent_steps:
                self._descend(cameras, archives, times, phase, kept_up)
        found = [Found(self.frontier(arch, t), k, self.near_deadline(arch, t))
                 for arch, t, k in zip(archives, times, kept_up, strict=True)]
        self.state.views_done += len(cameras)
        self.steps_done = max(self.steps_done, steps_before + stage_steps)  # searches that ended early
        self.report(phase)
        return found

    def frontier(self, archive: Archive, times: dict[Indices, float]) -> Points:
        """The two-tier frontier of every setting a search evaluated: the meeting tier, then the slow
        tier, each power ascending (ties in both objectives: the first evaluated)."""
        xs, objectives = archive.arrays()
        if not xs:
            return []
        fast, slow = frontier_tiers(objectives[:, 0], objectives[:, 1], archive.feasible_mask(xs))
        return [(self.space.expand(xs[i]), float(objectives[i, 0]), float(objectives[i, 1]), times[xs[i]])
                for i in fast + slow]

    def near_deadline(self, archive: Archive, times: dict[Indices, float]) -> Points:
        """The slow settings of ``archive`` that the display resolution may find real-time, for the
        display pricing to try (:func:`.builder.near_to_price`): those that miss the frame rate with a
        frame time at most :data:`NEAR_DEADLINE` times the deadline and are more accurate than every
        setting that keeps up, on their front of error against frame time (no other one both more
        accurate and faster), error ascending. None without a frame-rate target, or when a setting that
        keeps up is as accurate as Max. The frontier's slow tier ranks by power, and near the deadline
        the slow settings all draw about the full-speed power, so the tier keeps the most accurate and
        drops these."""
        fps = self.ev.fps
        xs, objectives = archive.arrays()
        if fps is None or not xs:
            return []
        meets = archive.feasible_mask(xs)
        best = float(objectives[meets, 0].min()) if meets.any() else math.inf
        if best <= 0.0:
            return []
        limit = NEAR_DEADLINE / float(fps)
        near = [i for i in np.flatnonzero(~meets)
                if objectives[i, 0] < best and times.get(xs[i], math.inf) <= limit]
        near.sort(key=lambda i: (objectives[i, 0], times[xs[i]]))
        out: Points = []
        fastest = math.inf
        for i in near:  # error ascending: on the front when faster than every more accurate one
            if times[xs[i]] < fastest:
                fastest = times[xs[i]]
                out.append((self.space.expand(xs[i]), float(objectives[i, 0]), float(objectives[i, 1]),
                            float(times[xs[i]])))
        return out

    def meeting_tier(self, points: Points) -> Points:
        """The points of a frontier that keep up with the run's frame rate (all of them when none
        does): what warm starts and frontier comparisons read, so the slow tier adds to the searches'
        results without steering them."""
        return split_by_rate(points, self.ev.fps)[0]

    def keeps_up(self, ev: Any) -> bool:
        """Whether an evaluation's frame time meets the run's target frame rate."""
        return meets_frame_rate(ev.frame_time_s, self.ev.fps)

    def probes(self, archive: Archive) -> list[Indices]:
        """Settings (free indices) between the most accurate setting of ``archive`` that keeps up and
        the maximum-quality one, not yet evaluated: Max with each free parameter stepped one value
        towards its cheap end, then Max moved :data:`PROBE_CHAIN` of the way (per index, rounded)
        towards that real-time setting. None unless the archive holds settings that keep up and
        settings that miss the rate (no frame-rate target missed: no slow tier to fill), or when one
        that keeps up is as accurate as Max. At most the
        number of free parameters plus ``len(PROBE_CHAIN)`` (11 on the default space)."""
        tiers = self._both_tiers(archive)
        if tiers is None:
            return []
        xs, objectives, meets = tiers
        ok = np.flatnonzero(meets)
        best = xs[int(ok[np.lexsort((objectives[ok, 1], objectives[ok, 0]))[0]])]  # least error, then power
        top = self.space.restrict(self.space.max_quality_indices())
        out = self.steps_down(top)
        for f in PROBE_CHAIN:
            out.append(tuple(t + round(f * (b - t)) for t, b in zip(top, best, strict=True)))
        return [x for x in dict.fromkeys(out) if x not in archive]

    def _probe(self, cameras: Sequence[CameraSpec], archives: list[Archive],
               times: list[dict[Indices, float]], phase: str) -> list[Points]:
        """Every camera's :meth:`probes`, as one batch; those that miss the frame rate join its
        archive (the slow tier's candidates), those that keep up are returned, per camera, and stay out
        of it (the meeting tier stays the search's). One progress step per camera probed."""
        kept_up: list[Points] = [[] for _ in cameras]
        jobs = [(j, self.probes(a)) for j, a in enumerate(archives)]
        jobs = [(j, xs) for j, xs in jobs if xs]
        if not jobs:
            return kept_up
        self.check_cancel()
        res = iter(self.evaluate([(cameras[j], self.space.expand(x)) for j, xs in jobs for x in xs]))
        for j, xs in jobs:
            for x in xs:
                ev = next(res)
                if not self.keeps_up(ev):
                    archives[j].add(x, (ev.error, ev.power_w), False)
                    times[j][x] = ev.frame_time_s
                else:
                    kept_up[j].append((self.space.expand(x), float(ev.error), float(ev.power_w),
                                       float(ev.frame_time_s)))
            self.probes_evaluated += len(xs)
        self.steps_done += len(jobs)
        self.report(phase)
        return kept_up

    @staticmethod
    def _both_tiers(archive: Archive) -> tuple[list[Indices], np.ndarray, np.ndarray] | None:
        """The archive's settings, objectives and which keep up, when it holds settings on both sides of
        the frame rate and none that keeps up is as accurate as Max (nothing could be more accurate);
        else None: no slow region to probe or descend."""
        xs, objectives = archive.arrays()
        if not xs:
            return None
        meets = archive.feasible_mask(xs)
        if meets.all() or not meets.any() or objectives[meets, 0].min() <= 0.0:
            return None
        return xs, objectives, meets

    def descent_start(self, archive: Archive) -> Indices | None:
        """Where a camera's descent starts (free indices): max quality, under the probes' condition
        (:meth:`_both_tiers`); else None."""
        if self._both_tiers(archive) is None:
            return None
        return self.space.restrict(self.space.max_quality_indices())

    def steps_down(self, x: Indices) -> list[Indices]:
        """``x`` with one free parameter one value nearer its cheap end, each parameter in turn."""
        low = self.space.restrict(self.space.min_quality_indices())
        return [(*x[:i], v + (1 if lo > v else -1), *x[i + 1:])
                for i, (v, lo) in enumerate(zip(x, low, strict=True)) if v != lo]

    @staticmethod
    def best_step(at: tuple[float, float], steps: Sequence[tuple[float, float]]) -> int | None:
        """Which of ``steps`` ((error, frame time) each) a descent at ``at`` takes: the most frame time
        saved for the error added (plus :data:`DESCENT_ERROR_FLOOR`); None when none saves time."""
        e0, t0 = at
        best, best_gain = None, 0.0
        for k, (e, t) in enumerate(steps):
            if t < t0:
                gain = (t0 - t) / (max(0.0, e - e0) + DESCENT_ERROR_FLOOR)
                if gain > best_gain:
                    best, best_gain = k, gain
        return best

    def _descend(self, cameras: Sequence[CameraSpec], archives: list[Archive],
                 times: list[dict[Indices, float]], phase: str, kept_up: list[Points]) -> None:
        """Every camera's descent from max quality toward the frame rate, in lock-step: at each step the
        settings one parameter one value cheaper than where it stands are evaluated and it moves to the
        one that saves the most frame time for the error it adds (:meth:`best_step`), at most
        ``descent_steps`` steps or until it keeps up. Steps that miss the rate join the archive (the slow
        tier's candidates); those that keep up join ``kept_up``, as the probes' do.

        The search's small images hide what the lab's heavy cameras at 640x360 needed: their NSGA-II
        frontiers went from error 0.09 straight to a slow Max, while FSAA with 2 shadow rays and no AO,
        two parameters below Max, keeps up at error 0.003 there and was never evaluated
        (bench/RESULTS.md, "The lab at 640x360 with the search's descent from Max")."""
        at: dict[int, tuple[Indices, float, float]] = {}
        for j, a in enumerate(archives):
            x = self.descent_start(a)
            if x is not None and x in a and x in times[j]:
                at[j] = (x, a.points[x][0], times[j][x])
        for _ in range(self.descent_steps):
            jobs = [(j, self.steps_down(x)) for j, (x, _, _) in at.items()]
            jobs = [(j, xs) for j, xs in jobs if xs]
            if not jobs:
                break
            self.check_cancel()
            res = iter(self.evaluate([(cameras[j], self.space.expand(x)) for j, xs in jobs for x in xs]))
            for j, xs in jobs:
                evs = [next(res) for _ in xs]
                self.descent_evaluated += len(xs)
                known = {pt[0] for pt in kept_up[j]}
                for x, ev in zip(xs, evs, strict=True):
                    if not self.keeps_up(ev):
                        if x not in archives[j]:
                            archives[j].add(x, (ev.error, ev.power_w), False)
                            times[j][x] = ev.frame_time_s
                    elif self.space.expand(x) not in known:
                        kept_up[j].append((self.space.expand(x), float(ev.error), float(ev.power_w),
                                           float(ev.frame_time_s)))
                k = self.best_step(at[j][1:], [(float(ev.error), float(ev.frame_time_s)) for ev in evs])
                if k is None or self.keeps_up(evs[k]):
                    del at[j]  # nothing saves time, or real time reached
                else:
                    at[j] = (xs[k], float(evs[k].error), float(evs[k].frame_time_s))
            self.steps_done += len(jobs)
            self.report(phase)

    def _enumerate(self, cameras: Sequence[CameraSpec], phase: str, times: list[dict[Indices, float]]
                   ) -> list[Archive]:
        xs = enumerate_space(self.space.free_n_values)
        archives = [Archive() for _ in cameras]
        chunk = max(1, 256 // len(cameras))
        for start in range(0, len(xs), chunk):
            self.check_cancel()
            part = xs[start:start + chunk]
            res = self.evaluate([(cam, self.space.expand(x)) for cam in cameras for x in part])
            for j in range(len(cameras)):
                for k, x in enumerate(part):
                    ev = res[j * len(part) + k]
                    archives[j].add(x, (ev.error, ev.power_w), self.keeps_up(ev))
                    times[j][x] = ev.frame_time_s
            self.steps_done += len(cameras)
            self.report(phase)
        return archives

    def _nsga(self, cameras: Sequence[CameraSpec], warm: Sequence[list[Indices]], phase: str,
              generations: int | None, times: list[dict[Indices, float]]) -> list[Archive]:
        algos = []
        for w, cam in zip(warm, cameras, strict=True):
            cfg = NSGAConfig(self.nsga.population, generations or self.nsga.generations,
                             self.nsga.crossover_prob, self.nsga.mutation_prob,
                             camera_seed(self.nsga.seed, cam))
            # both ends of the space first (max quality anchors error 0, the cheapest the low-power
            # end), then the warm start
            ends = [self.space.max_quality_indices(), self.space.min_quality_indices()]
            init = list(dict.fromkeys(self.space.restrict(x) for x in [*ends, *w]))
            algos.append(NSGA2(self.space.free_n_values, cfg, init[: cfg.population]))
        while True:
            self.check_cancel()
            asks = [(j, a.ask()) for j, a in enumerate(algos) if not a.done]
            asks = [(j, b) for j, b in asks if b]
            if not asks:
                break
            res = self.evaluate([(cameras[j], self.space.expand(x)) for j, b in asks for x in b])
            k = 0
            for j, b in asks:
                part = res[k:k + len(b)]
                algos[j].tell([(r.error, r.power_w) for r in part], [self.keeps_up(r) for r in part])
                times[j].update((x, r.frame_time_s) for x, r in zip(b, part, strict=True))
                k += len(b)
            self.steps_done += len(asks)
            self.report(phase)
        return [a.archive for a in algos]
