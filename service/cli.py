"""Command line: ``render-budget optimize | query | serve | cache``.

``optimize`` builds a Pareto store for a scene and a camera path (progress bar on stderr, resumable:
evaluations persist in an SQLite cache). ``query`` looks a camera up in a store under a power or error
budget. ``serve`` starts the REST service. ``cache stats | prune`` shows or shrinks an evaluation cache
(the command line's own, or a service's with ``--data-dir``). Camera-path JSON: see
:mod:`service.camera_path`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from service import options
from service.camera_path import CameraPath
from service.eval_cache import DEFAULT_MAX_BYTES, EvalCache
from service.evaluation import load_scene, read_scene
from service.executors import make_executor
from service.optimize import OptimizeConfig, optimize_path
from service.options import positive_number
from service.params import add_space_argument, search_space, space_from_arguments
from service.serve_options import add_serve_arguments, serve_overrides
from service.storage import EVAL_CACHE_NAME, read_active_scene_hashes
from service.store import ParetoStore
from service.verify import verify_store


def _default_cache() -> Path:
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "render-budget" / "eval-cache.sqlite"


_SIZE_UNITS = {"": 1, "k": 1024, "m": 1024**2, "g": 1024**3, "t": 1024**4}


def byte_size(text: str) -> int:
    """``2G``, ``500M``, ``1.5GiB``, ``4096``: a size in bytes (binary units)."""
    t = text.strip().lower().removesuffix("b").removesuffix("i")
    unit = t[-1:] if t[-1:] in _SIZE_UNITS and not t[-1:].isdigit() else ""
    try:
        value = float(t[: len(t) - len(unit)]) * _SIZE_UNITS[unit]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a size: {text!r} (e.g. 2G, 500M, 4096)") from None
    if not (math.isfinite(value) and value >= 1):
        raise argparse.ArgumentTypeError(f"size must be at least 1 byte, got {text!r}")
    return int(value)


def _finite(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return v


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if w < 8 or h < 8:
        raise argparse.ArgumentTypeError(f"must be at least 8x8, got {text!r}")
    return w, h


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="render-budget", description="Power-optimal ray-tracing settings along "
                                "camera paths, from a simulated mobile ray-tracing GPU.")
    sub = p.add_subparsers(dest="command", required=True)

    o = sub.add_parser("optimize", help="build a Pareto store for a scene and a camera path")
    o.add_argument("scene", type=Path, help="scene file (.rbscene from the add-on, .glb, .gltf or .obj)")
    o.add_argument("--path", type=Path, required=True, help="camera-path JSON")
    o.add_argument("--out", type=Path, required=True, help="where to write the store (JSON)")
    o.add_argument("--profile", default="mobile", help="hardware profile name or file (default: mobile)")
    o.add_argument("--fps", type=positive_number, default=30.0, help="frame rate the power is measured at")
    options.add_arguments(o)
    o.add_argument("--parameters", default=None, help="comma-separated parameters to search (default: all)")
    add_space_argument(o)
    o.add_argument("--cache", type=Path, default=None, help=f"evaluation cache (default {_default_cache()})")
    o.add_argument("--cache-max-bytes", type=byte_size, default=DEFAULT_MAX_BYTES, metavar="SIZE",
                   help="evaluation cache cap; least recently used cameras are evicted past it (default 2G)")
    o.add_argument("--dask-scheduler", default=None, metavar="ADDR", help="evaluate on a Dask cluster")
    o.add_argument("--workers", type=int, default=1, help="local worker processes (default 1: in-process)")
    o.add_argument("--threads", type=int, default=None, help="tracer threads per render")
    o.add_argument("--no-progress", action="store_true", help="no progress bar")

    q = sub.add_parser("query", help="settings for a camera from a store under a budget")
    q.add_argument("store", type=Path)
    q.add_argument("--position", type=_finite, nargs=3, required=True, metavar=("X", "Y", "Z"))
    g = q.add_mutually_exclusive_group(required=True)
    g.add_argument("--direction", type=_finite, nargs=3, metavar=("DX", "DY", "DZ"))
    g.add_argument("--matrix", type=_finite, nargs=16, metavar="M", help="Blender matrix_world, row-major")
    q.add_argument("--fov", type=positive_number, default=None, metavar="DEG", help="vertical field of view")
    b = q.add_mutually_exclusive_group(required=True)
    b.add_argument("--power-budget", type=_finite, metavar="W")
    b.add_argument("--error-budget", type=_finite, metavar="E")
    for opt in options.QUERY_OPTIONS:
        options.add_argument(q, opt)
    q.add_argument("--json", action="store_true", help="print JSON")

    v = sub.add_parser("verify", help="render sampled path frames with the store's settings at the path's "
                       "resolution and set the measured error and power against the store's predictions")
    v.add_argument("store", type=Path)
    v.add_argument("--scene", type=Path, required=True, help="the store's scene file")
    v.add_argument("--path", type=Path, required=True, help="camera-path JSON")
    vb = v.add_mutually_exclusive_group(required=True)
    vb.add_argument("--power-budget", type=positive_number, metavar="W")
    vb.add_argument("--error-budget", type=positive_number, metavar="E")
    v.add_argument("--frames", type=int, default=8, help="path frames to render, spread evenly (default 8)")
    v.add_argument("--resolution", type=_size, default=None, metavar="WxH",
                   help="render at this size instead of the path's own")
    v.add_argument("--threads", type=int, default=None, help="tracer threads per render")
    for opt in options.QUERY_OPTIONS:
        options.add_argument(v, opt)
    v.add_argument("--json", type=Path, default=None, metavar="FILE", help="also write the report as JSON")

    add_serve_arguments(sub.add_parser("serve", help="run the REST service"))

    c = sub.add_parser("cache", help="size of an evaluation cache, or shrink it")
    c_sub = c.add_subparsers(dest="cache_command", required=True)
    for name, what in (("stats", "entries, scenes, cameras, bytes in use and on disk"),
                       ("prune", "evict least recently used cameras down to --max-bytes, then VACUUM")):
        cp = c_sub.add_parser(name, help=what)
        where = cp.add_mutually_exclusive_group()
        where.add_argument("--cache", type=Path, default=None,
                           help=f"cache file (default {_default_cache()})")
        where.add_argument("--data-dir", type=Path, default=None,
                           help="a service's data directory (its running jobs' evaluations are kept)")
        if name == "prune":
            cp.add_argument("--max-bytes", type=byte_size, default=DEFAULT_MAX_BYTES, metavar="SIZE",
                            help="size to prune to (default 2G)")
        else:
            cp.add_argument("--json", action="store_true", help="print JSON")
    return p


#: Serve options that are settings of the service (``service.api.config.Settings``); each may also come
#: from its RENDER_BUDGET_* environment variable, which an option given on the command line overrides.
class _Bar:
    """A one-line progress bar on stderr."""

    def __init__(self, enabled: bool) -> None:
        forced = os.environ.get("RENDER_BUDGET_BAR") == "1"
        self.enabled = enabled and (sys.stderr.isatty() or forced)
        self.last = 0.0

    def __call__(self, p: Any) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self.last < 0.2 and p.phase != "done"):
            return
        self.last = now
        n = int(30 * p.fraction)  # the whole run's, display pricing included
        eta = f"{p.estimate_s:6.0f}s left" if p.estimate_s is not None else "   ...    "
        sys.stderr.write(f"\r[{'#' * n}{'.' * (30 - n)}] {p.views_done}/{p.views_planned} views, "
                         f"{p.evaluations} renders, {p.cache_hits} cached, {eta} {p.phase[:28]:<28}")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def _optimize(args: argparse.Namespace) -> int:
    path = CameraPath.load(args.path)
    handle = load_scene(args.scene, ship_bytes=bool(args.dask_scheduler))
    space = search_space(space_from_arguments(args.space))
    if args.parameters:
        space = space.subset([n.strip() for n in args.parameters.split(",") if n.strip()])
    config = OptimizeConfig(**options.from_arguments(args), profile=args.profile, fps=args.fps,
                            threads=args.threads)
    bar = _Bar(not args.no_progress)
    with EvalCache(args.cache or _default_cache(), max_bytes=args.cache_max_bytes,
                   protected=lambda: [handle.content_hash]) as cache:
        executor = make_executor(args.dask_scheduler, args.workers)
        try:
            store = optimize_path(handle, path, space, config, cache=cache, executor=executor, progress=bar)
        finally:
            bar.close()
            executor.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    text = store.to_json()
    args.out.write_text(text, encoding="utf-8")
    st = store.stats()
    print(f"wrote {args.out}: {st['size_bytes'] / 1024:.1f} KB, depth {st['depth']}, "
          f"{st['corners']} corners, {st['views']} views ({store.meta['views_optimised']} optimised), "
          f"{store.meta['evaluations']} renders, {store.meta['cache_hits']} cache hits, "
          f"{store.meta['elapsed_s']:.1f} s")
    fixed = store.meta.get("fixed_parameters") or {}
    for name, why in fixed.items():
        print(f"  left out {name}: {why}")
    return 0


def _query(args: argparse.Namespace) -> int:
    store = ParetoStore.from_json(args.store.read_bytes())
    matrix = None
    if args.matrix is not None:
        matrix = [args.matrix[i * 4:(i + 1) * 4] for i in range(4)]
    fov = math.radians(args.fov) if args.fov is not None else None
    r = store.lookup(args.position, direction=args.direction, matrix=matrix, fov=fov,
                     power_budget=args.power_budget, error_budget=args.error_budget,
                     **options.query_from_arguments(args))
    target = r.fps_target
    out = {"settings": r.settings, "indices": list(r.indices), "packed": r.packed, "power_w": r.power_w,
           "error": r.error, "clamped": r.clamped, "infeasible": r.infeasible, "corner": r.corner,
           "view": r.view, "frame_time_s": r.frame_time_s, "fps": r.fps, "fps_target": target,
           "meets_fps": r.meets_fps, "priority": r.priority, "error_margin": r.error_margin,
           "power_margin": r.power_margin,
           "expected_power_w": r.expected_power_w, "expected_error": r.expected_error,
           **store.figures.fields()}  # which display the figures hold for (as the REST answer says it)
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in r.settings.items():
            print(f"{k:>22}: {v}")
        print(f"{'predicted power':>22}: {r.expected_power_w:.4f} W (at most {r.power_w:.4f} W)")
        print(f"{'predicted error':>22}: {r.expected_error:.5f} (1 - SSIM; at most {r.error:.5f})")
        if r.fps is None:
            print(f"{'frame rate':>22}: unknown (the store predates frame times; target {target:g} fps)")
        else:
            print(f"{'frame rate':>22}: {r.fps:.1f} of {target:g} fps ({1e3 * r.frame_time_s:.1f} ms a "
                  "frame)")
        print(f"{'priority':>22}: {options.PRIORITY_LABELS[r.priority]}")
        if r.error_margin:
            print(f"{'error margin':>22}: {r.error_margin:g} (settings searched under "
                  f"{r.searched_budget:g})")
        if r.power_margin:
            print(f"{'power margin':>22}: {100 * r.power_margin:g} % of the budget (settings searched under "
                  f"{r.searched_budget:g} W)")
        print(f"{'figures':>22}: {store.figures.label()}")
        if r.meets_fps is False:
            why = ("the budget comes first: no setting within it keeps up with" if r.priority == "budget"
                   else "no setting of this view keeps up with")
            print(f"{'note':>22}: {why} {target:g} fps; the power is drawn at the frame rate shown")
        if r.clamped:
            print(f"{'note':>22}: clamped: camera outside the optimised region")
        if r.infeasible:
            within = "the budget less its margin" if r.error_margin or r.power_margin else "the budget"
            print(f"{'note':>22}: infeasible: nothing meets {within}, nearest returned")
    return 0


def _verify(args: argparse.Namespace) -> int:
    store = ParetoStore.from_json(args.store.read_bytes())
    path = CameraPath.load(args.path)
    scene = read_scene(args.scene)

    def progress(done: int, total: int) -> None:
        print(f"  rendered frame {done}/{total}", file=sys.stderr, flush=True)

    report = verify_store(scene, store, path, error_budget=args.error_budget, power_budget=args.power_budget,
                          frames=args.frames, resolution=args.resolution, threads=args.threads,
                          progress=progress, **options.query_from_arguments(args))
    print(report.table())
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report.to_dict(), indent=1), encoding="utf-8")
    return 0


def _cache(args: argparse.Namespace) -> int:

    if args.data_dir is not None:
        path = args.data_dir / EVAL_CACHE_NAME
        protected = read_active_scene_hashes(args.data_dir)
    else:
        path, protected = args.cache or _default_cache(), []
    if not path.is_file():
        raise FileNotFoundError(f"no evaluation cache at {path}")
    with EvalCache(path, max_bytes=None, protected=lambda: protected) as cache:
        before = cache.stats()
        if args.cache_command == "stats":
            if args.json:
                print(json.dumps(before))
            else:
                print(f"{path}: {before['entries']} evaluations of {before['cameras']} cameras in "
                      f"{before['scenes']} scenes; {_mib(before['size_bytes'])} in use, "
                      f"{_mib(before['file_bytes'])} on disk")
            return 0
        deleted = cache.prune(args.max_bytes)
        after = cache.stats()
    print(f"{path}: evicted {deleted} evaluations; {_mib(before['file_bytes'])} -> "
          f"{_mib(after['file_bytes'])} on disk, {after['entries']} evaluations left"
          + (f" ({len(protected)} scenes of running jobs kept)" if protected else ""))
    return 0


def _mib(n: int | None) -> str:
    return "?" if n is None else f"{n / 1024**2:.1f} MiB"


def _serve(args: argparse.Namespace) -> int:
    from service.api.server import run  # lazy: the web stack is heavy and only `serve` needs it

    run(serve_overrides(args), log_level=args.log_level)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "optimize":
            return _optimize(args)
        if args.command == "query":
            return _query(args)
        if args.command == "cache":
            return _cache(args)
        if args.command == "verify":
            return _verify(args)
        return _serve(args)
    except (ValueError, FileNotFoundError, IsADirectoryError) as exc:
        print(f"render-budget {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"render-budget {args.command}: interrupted (finished evaluations are cached)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
