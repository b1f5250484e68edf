"""The product's main job end to end: ``python -m tools.demo [--scene teapot] [--out out/demo]``.

``make demo`` and ``make report SCENE=...`` run this command-line shell over public entry points:

1. builds the scene with Blender's bpy module (``python -m blend_scenes.build --scene NAME``, cached);
2. starts ``render-budget serve`` on 127.0.0.1 (a free port, data and SQLite caches in ``var/service``);
3. uploads the scene (its render-budget scene file, as the add-on sends it) and optimises its camera
   path as a service job (the optimiser options of ``service.options`` given on the command line, the
   service's defaults for the rest;
   ``addon.core.job_runner`` follows and cancels it);
4. runs the evaluation campaign (``addon.core.campaign``: the same code as the Blender add-on's
   *Evaluate Path*): the paper's four presets, the store under a power budget and under an error budget,
   the report folder (Table 3, per-frame CSV, plots, sample frames, store, summary, Table 2);
5. verifies the store (POST /stores/{id}/verify): sampled path frames rendered at the size the store's
   figures were priced at, with the settings it picks under the error budget, measured against its
   predictions (``verify.md``, ``verify.json`` in the report folder);
6. stops the service, also on failure, Ctrl-C or SIGTERM.

The error budget is issue 7's 0.02; the power budget is placed between the Min and Max presets' measured
powers or between the store frontiers' ends, never tuned on the budget modes' results. Nothing here
imports bpy: the scene build runs in a child process.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import sim_core
from addon.core import campaign, campaign_targets, report
from addon.core.client import ServiceError
from addon.core.job_runner import JobRequest, follow_job
from addon.core.local_service import LocalService, free_port
from service import options as option_schema
from service.camera_path import CameraPath
from service.options import JOB_STALL_TIMEOUT_S, positive_number
from service.params import add_space_argument, space_from_arguments
from service.store import FiguresSize
from service.verify import markdown

REPO_ROOT = Path(__file__).resolve().parent.parent
SCENES_DIR = REPO_ROOT / "blend_scenes" / "build"
#: The data folder's record of the jobs its demo runs submitted, by request. A demo killed outright (a
#: crash, a lost session: no cancel reaches its service) leaves its job running in the data folder, and
#: the next start of the service takes it up again; a rerun that submitted the same request anew had both
#: run at once on the same workers, each rendering what the other did (the village at 1280x720: half an
#: hour of both cores spent twice before one was cancelled by hand).
JOBS_RECORD = "demo-jobs.json"


def say(text: str = "") -> None:
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="teapot", help="a blend_scenes scene (default: teapot)")
    ap.add_argument("--out", type=Path, default=None, help="report folder (default: out/demo)")
    ap.add_argument("--data-dir", type=Path, default=REPO_ROOT / "var" / "service",
                    help="the local service's data folder (scenes, stores, SQLite caches)")
    ap.add_argument("--resolution", type=campaign.parse_size, default=None,
                    help="preview resolution WxH for optimisation and evaluation (sets --eval-width and "
                         "--eval-height; default: height 36, width from the path's aspect)")
    ap.add_argument("--frames", type=int, default=90,
                    help="evaluate about this many path frames, evenly spaced (default 90; 0 = all)")
    ap.add_argument("--error-budget", type=float, default=campaign_targets.TARGET_ERROR)
    ap.add_argument("--power-budget", type=float, default=None,
                    help="watts (default: automatic, see --power-budget-from)")
    ap.add_argument("--power-budget-from", choices=("presets", "store"), default="presets",
                    help="automatic power budget between the Min and Max presets' measured mean powers "
                         "(presets, default) or between the store frontiers' cheapest and most accurate "
                         "predicted points (store)")
    ap.add_argument("--power-fraction", type=float, default=0.4,
                    help="automatic power budget: this fraction of the way from the cheap end to the "
                         "accurate end (default 0.4, where the paper's Elven Ruins demo put its budget)")
    ap.add_argument("--filter-period", type=float, default=2.0, help="temporal filter T (s)")
    ap.add_argument("--samples", type=int, default=3, help="sample frames written as PNG and EXR")
    ap.add_argument("--sample-resolution", type=campaign.parse_size, default=None,
                    help="sample frames' WxH (default: height 72, width from the path's aspect)")
    ap.add_argument("--concurrency", type=int, default=2, help="evaluations in flight")
    ap.add_argument("--profile", choices=sorted(sim_core.list_profiles()), default="mobile",
                    help="hardware profile the store is searched and priced for, and the evaluation "
                         "measured on (default: mobile)")
    lookup = ap.add_argument_group("the store lookup's query options (both budget modes and verify)")
    for opt in option_schema.QUERY_OPTIONS:  # --fps (default: the store's own), --priority, --error-margin
        option_schema.add_argument(lookup, opt)
    ap.add_argument("--verify-frames", type=int, default=6,
                    help="path frames the store is verified on at its figures' resolution (0: skip)")
    ap.add_argument("--job-timeout", type=positive_number, default=None,
                    help="seconds before giving up on the optimisation job however it progresses (default: "
                         "no limit; a heavy scene's job runs for hours)")
    ap.add_argument("--stall-timeout", type=positive_number, default=JOB_STALL_TIMEOUT_S,
                    help="seconds the running job may go without progress before it is given up "
                         f"(default {JOB_STALL_TIMEOUT_S:.0f}; it reports each view and camera done)")
    ap.add_argument("--request-timeout", type=positive_number, default=DEMO_REQUEST_TIMEOUT_S,
                    help="seconds one request to the local service may take: a render at the path's own "
                         "size of a heavy frame on shared cores takes minutes (default "
                         f"{DEMO_REQUEST_TIMEOUT_S:.0f})")
    ap.add_argument("--skip-build", action="store_true", help="use the built scene as it is")
    optimiser = ap.add_argument_group(
        "optimiser options (the service's defaults unless given, but the demo's own display height "
        f"{DEMO_DISPLAY_HEIGHT}, display points {DEMO_DISPLAY_POINTS}, guard frames {DEMO_GUARD_FRAMES}, "
        f"guard radius {DEMO_GUARD_RADIUS:g}, bridge points {DEMO_BRIDGE_POINTS} and slow points 1, or "
        f"{DEMO_DISPLAY_POINTS} under --priority budget)")
    option_schema.add_arguments(optimiser, with_defaults=False, left_out="the demo's own")
    add_space_argument(optimiser)
    return ap


#: The demo prices its store at this display height (width from the path's aspect; whole frames at this
#: size) and keeps this many points a frontier, unless --display-height / --display-points say otherwise:
#: a stated smaller size than the paths' 1280x720, so that ``make demo`` stays near its time budget on two
#: cores (full size: ``--display-height path``).
DEMO_DISPLAY_HEIGHT = 180
DEMO_DISPLAY_POINTS = 4
#: Path frames each frontier is also priced at besides its sample (the service's default is 2): on the
#: teapot's demo job a second guard changed no figure of Table 3 or verify by more than 0.0001 in error or
#: 0.001 W and cost a third of the pricing's CPU time (bench/RESULTS.md, "make demo under ten minutes").
DEMO_GUARD_FRAMES = 1
#: The guard radius (the service's default is 0.01): 0.05, at which the teapot's demo store prices no
#: frame more. 0.01 priced 95 settings more there (a minute of CPU from a copied data folder, for a job
#: that runs within a minute of its ten) and moved Table 3 by 0.1 % (52.4 % saved for 52.5 %, the same
#: mean error; bench/RESULTS.md, "A guard radius of 0.01").
DEMO_GUARD_RADIUS = 0.05
#: Settings priced between the priced points' error jumps, at most, a frontier (the service's default is
#: 8): none. On the teapot's demo job 8 raised the error budget's saving from 52.5 % to 61.3 % (at mean
#: error 0.0106) but took half again the job's CPU time; 2 gave 54.2 % at 0.0073 and took the demo to
#: 10 min 36 s on a fresh clone, over its 10 minutes (bench/RESULTS.md, "Bridging on the teapot's demo
#: job"). ``--bridge-points 8`` gives the service's pricing.
DEMO_BRIDGE_POINTS = 0
#: Seconds one request to the demo's local service may take. Evaluating one valley frame at the path's
#: own 1280x720, with the cores shared with another job, took over the 300 s this was before and stopped a
#: main job (bench/RESULTS.md, "The valley priced at the path's own 1280x720").
DEMO_REQUEST_TIMEOUT_S = 1800.0


def demo_slow_points(priority: str) -> int:
    """The slow points the demo's store prices unless --slow-points says: as many as its display points
    when its lookups put the budget first (the only priority that reads them), else max quality alone,
    which costs no render of its own (each was about a max-quality frame at every pricing camera: a fifth
    of the teapot demo's pricing time, bench/RESULTS.md)."""
    return DEMO_DISPLAY_POINTS if priority == "budget" else 1


def job_request(args: argparse.Namespace) -> JobRequest:
    """The optimisation job: the options given on the command line (the display height, points, guard
    frames, guard radius and bridge points defaulting to :data:`DEMO_DISPLAY_HEIGHT`,
    :data:`DEMO_DISPLAY_POINTS`, :data:`DEMO_GUARD_FRAMES`, :data:`DEMO_GUARD_RADIUS`,
    :data:`DEMO_BRIDGE_POINTS`, the slow points to :func:`demo_slow_points`);
    the service fills in the rest."""
    given = option_schema.from_arguments(args)
    given.setdefault("display_height", DEMO_DISPLAY_HEIGHT)
    given.setdefault("display_points", DEMO_DISPLAY_POINTS)
    given.setdefault("guard_frames", DEMO_GUARD_FRAMES)
    given.setdefault("guard_radius", DEMO_GUARD_RADIUS)
    given.setdefault("bridge_points", DEMO_BRIDGE_POINTS)
    given.setdefault("slow_points", demo_slow_points(args.priority))
    if args.resolution is not None:
        given["eval_width"], given["eval_height"] = args.resolution
    return JobRequest(profile=args.profile, options=given, space=space_from_arguments(args.space) or None)


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a running process and of its live and finished descendants (the
    service's evaluation workers): Linux /proc; None elsewhere."""
    stats: dict[int, list[str]] = {}
    try:
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    stats[int(entry.name)] = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                except (OSError, IndexError):
                    continue
    except OSError:
        return None
    if pid not in stats:
        return None
    children: dict[int, list[int]] = {}
    for p, f in stats.items():
        children.setdefault(int(f[1]), []).append(p)
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        f = stats[p]
        total += int(f[11]) + int(f[12]) + (int(f[13]) + int(f[14]) if p == pid else 0)
        todo.extend(children.get(p, []))
    return total / os.sysconf("SC_CLK_TCK")


def build_scene(name: str, skip: bool) -> tuple[Path, dict[str, Any]]:
    """Build (or reuse) the scene through bpy in a child process; returns its folder and statistics."""
    if not skip:
        cmd = [sys.executable, "-m", "blend_scenes.build", "--scene", name]
        proc = subprocess.run(cmd, cwd=REPO_ROOT, text=True, capture_output=True, check=False)
        for line in (proc.stdout + proc.stderr).splitlines():
            if line.strip():
                say(f"  {line}")
        if proc.returncode != 0:
            raise RuntimeError(f"scene build failed ({' '.join(cmd)} exited with {proc.returncode})")
    scene_dir = SCENES_DIR / name
    for f in (scene_dir / "scene.rbscene", scene_dir / "path.json"):
        if not f.is_file():
            raise FileNotFoundError(f"{f} is missing (build the scene: python -m blend_scenes.build "
                                    f"--scene {name})")
    stats_file = scene_dir / "stats.json"
    return scene_dir, (json.loads(stats_file.read_text()) if stats_file.is_file() else {})


def run(args: argparse.Namespace) -> dict[str, Any]:
    out = args.out or (REPO_ROOT / "out" / "demo")
    clock = campaign.Clock()
    say(f"== scene '{args.scene}' (blend_scenes, built through bpy; cached)")
    t = clock.start()
    scene_dir, stats = build_scene(args.scene, args.skip_build)
    path_doc = json.loads((scene_dir / "path.json").read_text())
    path = CameraPath.from_dict(path_doc)
    say(f"  {stats.get('summary', scene_dir / 'scene.rbscene')}")
    clock.stop("scene", t)

    request = job_request(args)
    resolution = campaign.size_for_path(path, request.option("eval_height"), request.option("eval_width"))
    # the service renders a job's evaluations on every core, like the add-on's local service
    service = LocalService(sys.executable, free_port(), args.data_dir, eval_workers=os.cpu_count() or 1)
    say(f"== service: render-budget serve on {service.url}, data in {args.data_dir}")
    try:  # from here on the service is stopped whatever happens (also Ctrl-C while it starts)
        service.start()
        clock.extra_cpu = lambda: process_cpu_s(service.process.pid) if service.process else None
        client = service.client(timeout_s=args.request_timeout)
        health = client.health()
        say(f"  up: version {health['version']}, executor {health['executor']}, "
            f"profiles {', '.join(health['profiles'])}")
        # the scene file the add-on sends: self-contained (the valley's HDRI travels inside it, where the
        # .glb only names the EXR next to it and an upload cannot carry that)
        info = client.upload_scene(scene_dir / "scene.rbscene")
        say(f"  scene {info['id'][:12]}: {info['stats'].get('triangles')} triangles; inert: "
            + (", ".join(info.get("inert_parameters") or {}) or "none"))

        say(f"== optimise the path ({len(path)} frames, {campaign_targets.path_duration(path):.1f} s) at "
            f"{resolution[0]}x{resolution[1]} through the service")
        t = clock.start()
        job, resumed = submit_or_resume(client, request.payload(info["id"], path_doc), args.data_dir)
        if resumed:
            say(f"  job {job['id']} resumed ({job['state']}: submitted by an earlier run that was killed; "
                "its finished renders are cached; the times below are this run's)")
        else:
            say(f"  job {job['id']} queued")
        last = [""]

        def show(update: Any) -> None:
            if update.text != last[0]:
                last[0] = update.text
                say(f"  {update.text}")

        per_view = request.option("population") * request.option("generations")
        job = follow_job(client, job, evals_per_view=per_view, progress=show, poll_s=1.0,
                         timeout_s=args.job_timeout, stall_s=args.stall_timeout)
        opt = clock.stop("optimise", t)
        store_text = client.store_text(job["store_id"])
        measured_at, power_at = campaign.measurement_sizes(store_text, resolution, path)
        spec = campaign.CampaignSpec(
            scene_id=info["id"], resolution=measured_at, power_resolution=power_at,
            frame_step=campaign.frame_step(len(path), args.frames), filter_period_s=args.filter_period,
            error_budget=args.error_budget, power_budget=args.power_budget,
            power_budget_from=args.power_budget_from, power_fraction=args.power_fraction,
            samples=args.samples, sample_resolution=args.sample_resolution, concurrency=args.concurrency,
            **option_schema.query_from_arguments(args))
        marks: set[int] = set()

        def progress(label: str, done: int, total: int) -> None:
            if 10 * done // max(1, total) not in marks:
                marks.add(10 * done // max(1, total))
                say(f"  {label}: {done}/{total} renders")

        pre = campaign_targets.Preprocessing(args.scene, stats.get("triangles"), opt["wall_s"], opt["cpu_s"])
        outcome = campaign.run(client, store_text, path, spec, out, title=args.scene, pre=pre, clock=clock,
                               progress=progress, say=say)
        summarise(outcome, out)
        if args.verify_frames > 0:
            verify(client, job["store_id"], path_doc, outcome.summary["store"]["meta"], args, out, clock)
        return outcome.summary
    finally:
        service.stop()
        say("service stopped")


def _unfinished(client: Any, job_id: Any) -> dict[str, Any] | None:
    """The service's job ``job_id`` while it is queued or running, else None (ended, or not held)."""
    if not isinstance(job_id, str):
        return None
    try:
        job = client.job(job_id)
    except ServiceError as exc:
        if exc.status != 404:  # (404: a job the data folder no longer holds)
            raise
        return None
    return job if job["state"] in ("queued", "running") else None


def submit_or_resume(client: Any, payload: dict[str, Any], data_dir: Path) -> tuple[dict[str, Any], bool]:
    """The job for ``payload``: the one an earlier run submitted when the service still has it queued or
    running (True), else a new one, recorded in the data folder's :data:`JOBS_RECORD` (False), which then
    keeps only the jobs still unfinished (an ended job is never followed again)."""
    digest = hashlib.sha256(json.dumps(payload, sort_keys=True).encode("utf-8")).hexdigest()
    record = Path(data_dir) / JOBS_RECORD
    try:
        known = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):  # none yet, or cut short: submit anew
        known = {}
    if not isinstance(known, dict):
        known = {}
    job = _unfinished(client, known.get(digest))
    if job is not None:
        return job, True
    job = client.submit_job(payload)
    known = {d: j for d, j in known.items() if d != digest and _unfinished(client, j) is not None}
    known[digest] = job["id"]
    tmp = record.with_name(f".{record.name}.{os.getpid()}")
    tmp.write_text(json.dumps(known, indent=1), encoding="utf-8")
    os.replace(tmp, record)
    return job, False


def verify(client: Any, store_id: str, path_doc: dict[str, Any], meta: dict[str, Any],
           args: argparse.Namespace, out: Path, clock: campaign.Clock) -> None:
    """The store's promises under the error budget, measured at the resolution its figures are for."""
    size = FiguresSize.from_meta(meta).resolution or path_doc["frames"][0]["resolution"]
    say(f"== verify the store: {args.verify_frames} path frames at {size[0]}x{size[1]} "
        f"(POST /stores/{{id}}/verify, error budget {args.error_budget})")
    t = clock.start()
    body = {"camera_path": path_doc, "error_budget": args.error_budget, "frames": args.verify_frames,
            "resolution": [int(v) for v in size],
            **option_schema.only_query_overrides(option_schema.query_from_arguments(args))}
    doc = client.verify(store_id, body, timeout_s=3600.0)
    spent = clock.stop("verify", t)
    text = markdown(doc)
    (out / "verify.md").write_text(f"# Verify: the store's predictions against renders\n\nStore figures "
                                   f"priced by: {meta.get('display_pricing_label', 'preview resolution')}; "
                                   f"{spent['wall_s']:.0f} s wall.\n\n{text}\n", encoding="utf-8")
    (out / "verify.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    for line in text.splitlines():
        say(f"  {line}")


def summarise(outcome: campaign.Outcome, out: Path) -> None:
    """The console's view of the report: Table 3, the targets, what was written."""
    s = outcome.summary
    st, meta = s["store"], s["store"]["meta"]
    say(f"  store: {st['size_bytes'] / 1024:.1f} KB, depth {st['depth']}, {st['corners']} corners, "
        f"{st['views']} views, {meta.get('evaluations')} renders ({meta.get('cache_hits')} cache hits)")
    say("")
    lookup = s["lookup"]
    priority = option_schema.PRIORITY_LABELS[lookup["priority"]].lower()
    say(report.table3_markdown(outcome.summaries, title=f"Table 3: {s['scene']} (budget modes looked up for "
                                                        f"{lookup['fps']:g} fps, {priority})"))
    for line in campaign_targets.target_lines(outcome.targets, st["size_bytes"]):
        say(line)
    for line in s.get("real_time_notes", ()):
        say(f"- {line}")
    total = next(p for p in s["phases"] if p["phase"] == "total")
    evaluate = next(p for p in s["phases"] if p["phase"] == "evaluate")
    say(f"\nwrote {out}/: report.md, per_frame.csv, power_over_time.png, error_over_time.png, store.json, "
        f"summary.json, frames/ ({len(outcome.samples)} files); total {total['wall_s']:.0f} s wall, "
        f"{total['cpu_s']:.0f} s CPU (evaluation {evaluate['wall_s']:.0f} s)")


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def on_term(signum: int, _frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")  # leave as Ctrl-C does: cancel the job, stop the service

    signal.signal(signal.SIGTERM, on_term)
    try:
        run(args)
    except KeyboardInterrupt:
        sys.stderr.write("demo interrupted; the service was stopped\n")
        return 130
    except Exception as err:  # one clear line, non-zero status; the service is already stopped
        sys.stderr.write(f"demo failed: {type(err).__name__}: {err}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
