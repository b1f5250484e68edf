"""Headless batch runs of the add-on: optimize, evaluate, playback.

    blender -b scene.blend --python-exit-code 1 -P addon/batch.py -- optimize     # jobs on this computer
    python -m addon.batch --blend scene.blend optimize                            # with the bpy module
    python -m addon.batch --blend scene.blend --url http://host:8765 optimize     # on a remote service
    python -m addon.batch --blend scene.blend --workers 2 evaluate --out report/

Where jobs run (--url, --token, --workers, --data-dir, --timeout, --stall-timeout) comes before the
command: by default on this computer with the bundled core, or on the remote service at --url. Each
command's own options come after it (`python -m addon.batch optimize --help`). A job is given up when it
makes no progress for --stall-timeout seconds (or after --timeout in all, if given). ``evaluate`` runs the
evaluation campaign of ``make demo`` under the scene's power and error budgets and the store lookup's
frame-rate target and priority (``--fps``, ``--priority``: kept in the .blend, as playback and the render
engine use them; left out, the .blend's values stay, and ``--fps store`` sets a saved frame rate back to
the store's own) and writes the same report folder. Every option whose default is derived has a word that
sets a value saved in the .blend back to it: ``--fps store``, ``--eval-width auto`` (from the path's
aspect), ``--display-height path`` (the path's own resolution). Prints a text progress bar; exits non-zero
(with the reason on stderr) on any failure.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import importlib.util
import shutil
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

EXT_ID = "render_budget"
STAGED_REPO = "render_budget_batch"
_staged: list[Path] = []  # extension copies this run staged in the temp dir (removed at its end)


# -- text progress -------------------------------------------------------------------------------------
class ProgressBar:
    """One line that fills up; redrawn in place on a terminal, one line per change otherwise."""

    def __init__(self, label: str, width: int = 30, stream=None) -> None:
        self.label, self.width = label, width
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.last = ""

    def __call__(self, fraction: float, text: str = "") -> None:
        fraction = min(1.0, max(0.0, fraction))
        filled = round(self.width * fraction)
        line = f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:5.1f}% {text}"
        if line == self.last:
            return
        self.last = line
        self.stream.write(("\r" + line) if self.tty else (line + "\n"))
        self.stream.flush()

    def done(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


# -- extension loading ---------------------------------------------------------------------------------
def ensure_extension(bpy: ModuleType) -> str:
    """The enabled extension's module name: an installed copy if enabled, else stage it from the source
    tree and enable it as a dev repository (the source tree's Python packages are then importable)."""
    for name in bpy.context.preferences.addons.keys():
        if name.endswith("." + EXT_ID):
            return name
    import addon_utils  # lazy: a Blender module, like bpy (this script is handed bpy by main)

    for mod in addon_utils.modules(refresh=False):
        if mod.__name__.endswith("." + EXT_ID):
            addon_utils.enable(mod.__name__, default_set=True, handle_error=_raise)
            return mod.__name__
    repo_root = Path(__file__).resolve().parent.parent
    tools = repo_root / "tools"
    if not (tools / "build_extension.py").is_file():
        raise RuntimeError("the render_budget extension is not installed and no source tree is next to this "
                           "script: install the zip first")
    if importlib.util.find_spec("service") is None or importlib.util.find_spec("sim_core") is None:
        raise RuntimeError("the render_budget extension is not installed in this Blender: install the zip "
                           "(make addon, then Install from Disk), or run this script with the bpy module "
                           "of the checkout's .venv")
    sys.path.insert(0, str(tools))
    try:
        build_extension = importlib.import_module("build_extension")
    finally:
        sys.path.remove(str(tools))
    stage_dir = Path(tempfile.mkdtemp(prefix="render-budget-batch-"))
    _staged.append(stage_dir)
    build_extension.stage(stage_dir)
    repos = bpy.context.preferences.extensions.repos
    repos.new(name=STAGED_REPO, module=STAGED_REPO, custom_directory=str(stage_dir), source="USER")
    name = f"bl_ext.{STAGED_REPO}.{EXT_ID}"
    addon_utils.enable(name, default_set=True, handle_error=_raise)
    return name


def remove_staged_extension(bpy: ModuleType) -> None:
    """Undo :func:`ensure_extension`'s staging: disable the copy, drop its repository, delete the folder
    (a batch run leaves nothing in the temp dir)."""
    if not _staged:
        return
    import addon_utils  # lazy: a Blender module, like bpy

    addon_utils.disable(f"bl_ext.{STAGED_REPO}.{EXT_ID}", default_set=True)
    repos = bpy.context.preferences.extensions.repos
    for repo in [r for r in repos if r.module == STAGED_REPO]:
        repos.remove(repo)
    while _staged:
        shutil.rmtree(_staged.pop(), ignore_errors=True)


def _raise(exc: BaseException) -> None:
    raise exc


# -- arguments -----------------------------------------------------------------------------------------
_SCHEMA_MODULE = "render_budget_options"


def _option_schema() -> ModuleType:
    """The optimiser's option schema (service/options.py, stdlib only): from the source tree or an
    installed project, else the copy inside a staged extension next to this file (loaded once: the
    parser and the scene options compare against its :data:`DERIVE`)."""
    try:  # lazy, with a fallback: a script inside Blender may not see the project's packages
        from service import options
    except ImportError:
        if _SCHEMA_MODULE in sys.modules:
            return sys.modules[_SCHEMA_MODULE]
        here = Path(__file__).resolve().parent
        for path in (here.parent / "service" / "options.py",):
            if path.is_file():
                spec = importlib.util.spec_from_file_location(_SCHEMA_MODULE, path)
                assert spec is not None and spec.loader is not None
                options = importlib.util.module_from_spec(spec)
                sys.modules[spec.name] = options  # dataclasses look their module up
                spec.loader.exec_module(options)
                break
        else:
            raise ImportError("service/options.py not found next to the batch script") from None
    return options


#: What an option left out of a command line does here (its help says so, next to its derived word).
_KEPT = "the .blend's value stays"


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="batch", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--blend", help="open this .blend first (needed with the bpy module)")
    svc = ap.add_argument_group("where jobs run (default: this computer, with the bundled core)")
    svc.add_argument("--url", help="a remote render-budget service instead")
    svc.add_argument("--token", default="", help="the remote service's token")
    svc.add_argument("--workers", type=int, help="local evaluation processes (default: one per CPU core)")
    svc.add_argument("--data-dir", help="local jobs' scenes and evaluation cache (default: the extension's "
                                        "user folder)")
    schema = _option_schema()
    svc.add_argument("--timeout", type=schema.positive_number, default=None,
                     help="seconds before giving up on a job however it progresses (default: no limit)")
    svc.add_argument("--stall-timeout", type=schema.positive_number, default=schema.JOB_STALL_TIMEOUT_S,
                     help="seconds a running job may go without progress before it is given up (default "
                          f"{schema.JOB_STALL_TIMEOUT_S:.0f})")
    sub = ap.add_subparsers(dest="command", required=True)

    def budget(p: argparse.ArgumentParser) -> None:
        p.add_argument("--budget-mode", choices=("power", "error"))
        p.add_argument("--budget", type=float, help="watts (power) or 1 - SSIM (error)")
        p.add_argument("--filter-period", type=float, help="temporal filter T in seconds")
        for query_option in _option_schema().QUERY_OPTIONS:  # the store lookup's --fps and --priority
            _option_schema().add_argument(p, query_option, with_default=False, left_out=_KEPT)

    opt = sub.add_parser("optimize", help="record the path if needed, optimise, keep the store, save")
    budget(opt)
    opt.add_argument("--profile")
    _option_schema().add_arguments(opt, with_defaults=False, left_out=_KEPT)
    opt.add_argument("--resolution", help="evaluation resolution WxH, e.g. 64x36 (sets --eval-width, "
                     "--eval-height)")
    opt.add_argument("--space", action="append", metavar="NAME=V1,V2,...",
                     help="search these values of a parameter instead of the listed ones, e.g. "
                          "shadow_samples=0,1,2,4,16 (repeat per parameter; kept in the .blend's parameter "
                          "list)")
    opt.add_argument("--frame-step", type=int)
    opt.add_argument("--record", action="store_true", help="re-record the path from the camera animation")
    opt.add_argument("--save-as", help="save the .blend here (default: overwrite the opened file)")
    opt.add_argument("--no-save", action="store_true")
    opt.add_argument("--store-out", help="also write the store JSON here")

    ev = sub.add_parser("evaluate", help="evaluate the path against the presets; write a report folder")
    budget(ev)
    ev.add_argument("--out", required=True)
    ev.add_argument("--frame-step", type=int)
    ev.add_argument("--resolution", help="evaluation resolution WxH")
    ev.add_argument("--no-samples", action="store_true", help="skip the sample frames")

    pb = sub.add_parser("playback", help="play the frame range through the store; per-frame CSV")
    budget(pb)
    pb.add_argument("--out", help="CSV of the per-frame settings and predictions")
    return ap


def _apply_scene_options(ext: str, props, args: argparse.Namespace) -> None:
    if getattr(args, "budget_mode", None):
        props.budget_mode = args.budget_mode.upper()
    if getattr(args, "budget", None) is not None:
        # checked before Blender's property limits would silently clamp the value
        importlib.import_module(f"{ext}.core.playback_logic").validate_budget(props.budget_mode, args.budget)
        if props.budget_mode == "POWER":
            props.power_budget = args.budget
        else:
            props.error_budget = args.budget
    for name in ("filter_period", "profile", "frame_step"):
        value = getattr(args, name, None)
        if value is not None:
            setattr(props, name, value)
    set_option = importlib.import_module(f"{ext}.properties").set_option
    if getattr(args, "resolution", None):
        parse_size = importlib.import_module(f"{ext}.core.campaign").parse_size
        args.eval_width, args.eval_height = parse_size(args.resolution)
    schema = _option_schema()
    for opt in (*schema.PUBLIC, *schema.QUERY_OPTIONS):  # each checked here; together when the job is built
        value = getattr(args, opt.name, None)  # None: not given, the .blend's value stays
        if value is not None:  # DERIVE (--fps store, --eval-width auto, ...): back to None, "derive it"
            set_option(props, opt.name, None if value is schema.DERIVE else value)


def _configure_service(bpy: ModuleType, ext: str, args: argparse.Namespace) -> None:
    prefs = importlib.import_module(f"{ext}.preferences").get(bpy.context)
    if args.url:
        prefs.service_mode = "REMOTE"
        prefs.url, prefs.token, prefs.timeout_s = args.url, args.token, 120
    else:
        prefs.service_mode = "LOCAL"
        if args.workers is not None:
            if args.workers < 1:
                raise ValueError(f"--workers must be >= 1, got {args.workers}")
            prefs.local_workers = args.workers
        prefs.data_dir = args.data_dir or ""


# -- commands ------------------------------------------------------------------------------------------
def cmd_optimize(bpy: ModuleType, ext: str, args: argparse.Namespace) -> int:
    scene = bpy.context.scene
    ops = importlib.import_module(f"{ext}.ops_optimize")
    cp = importlib.import_module(f"{ext}.camera_path")
    sp = importlib.import_module(f"{ext}.service_process")
    if args.record:
        if scene.camera is None:
            raise ValueError("the scene has no active camera")
        cp.store_path(scene, cp.sample_animation(scene, scene.camera, scene.render_budget.frame_step))
    if args.space:
        ops.set_parameter_values(scene, args.space)
    client = sp.client_for(bpy.context)
    bar = ProgressBar("optimize")
    t0 = time.monotonic()
    applied = ops.run_sync(scene, client, progress=lambda u: bar(u.fraction, u.text), timeout_s=args.timeout,
                           stall_s=args.stall_timeout)
    bar.done()
    sys.stdout.write(f"store: {applied.summary} ({time.monotonic() - t0:.1f} s)\n")
    if applied.shortfall:
        sys.stderr.write(f"warning: {applied.shortfall}\n")
    if args.store_out:
        Path(args.store_out).write_text(scene.render_budget.store_text.as_string(), encoding="utf-8")
    if not args.no_save:
        target = args.save_as or bpy.data.filepath
        if not target:
            raise ValueError("nothing to save to: pass --save-as or --no-save")
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(target).resolve()))
        sys.stdout.write(f"saved {target}\n")
    return 0


def cmd_evaluate(bpy: ModuleType, ext: str, args: argparse.Namespace) -> int:
    rep = importlib.import_module(f"{ext}.ops_report")
    sp = importlib.import_module(f"{ext}.service_process")
    client = sp.client_for(bpy.context)
    bar = ProgressBar("evaluate")
    written = rep.evaluate_scene(bpy.context.scene, client, args.out,
                                 progress=lambda d, t: bar(d / max(t, 1), f"{d}/{t} renders"),
                                 frame_step=args.frame_step, samples=not args.no_samples)
    bar.done()
    sys.stdout.write(Path(written["report"]).read_text(encoding="utf-8"))
    if "plots_skipped" in written:
        sys.stdout.write(f"plots skipped: {written['plots_skipped']}\n")
    return 0


def cmd_playback(bpy: ModuleType, ext: str, args: argparse.Namespace) -> int:
    scene = bpy.context.scene
    props = scene.render_budget
    if props.store_text is None:
        raise ValueError("no Pareto store in this .blend: run optimize first")
    if scene.camera is None:
        raise ValueError("the scene has no active camera")
    pb = importlib.import_module(f"{ext}.playback")
    pb.reset()
    rows = []
    frames = range(scene.frame_start, scene.frame_end + 1)
    bar = ProgressBar("playback")
    t0 = time.perf_counter()
    for i, f in enumerate(frames):
        scene.frame_set(f)  # the persistent handler does the work
        if props.playback_status.startswith("error"):
            raise ValueError(f"frame {f}: {props.playback_status}")
        rows.append((f, pb.scene_time(scene), props.active_indices, props.target_indices,
                     props.predicted_power, props.predicted_error, props.predicted_fps or None,
                     props.active_settings, props.target_fps or None,
                     "" if not props.predicted_fps else int(not props.slower_than_fps), props.priority))
        bar((i + 1) / len(frames), f"frame {f}")
    bar.done()
    elapsed = time.perf_counter() - t0
    figures = pb.figures_of(scene)  # the display the predictions hold for
    if args.out:
        with open(args.out, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(("frame", "time_s", "active_indices", "target_indices", "predicted_power_w",
                        "predicted_error", "predicted_fps", "settings", "fps_target", "meets_fps",
                        "priority", "predicted_for"))
            w.writerows((*row, figures) for row in rows)
    n = max(1, len(rows))
    rates = [r[6] for r in rows if r[6]]
    rate = f" at {sum(rates) / len(rates):.1f} fps" if rates else ""  # none: a store before frame times
    missed = sum(r[9] == 0 for r in rows)
    if missed:  # frames whose settings miss the frame-rate target (and why, under the priority)
        rate += (f" ({missed} frames miss {rows[0][8]:g} fps" +
                 (": budget first)" if props.priority == "budget" else ": no setting keeps up)"))
    sys.stdout.write(f"{len(rows)} frames, mean predicted power {sum(r[4] for r in rows) / n:.3f} W{rate}, "
                     f"mean predicted error {sum(r[5] for r in rows) / n:.4f} (for {figures}), "
                     f"{len({r[2] for r in rows})} distinct settings, {1e3 * elapsed / n:.3f} ms/frame "
                     f"(frame_set included)\n")
    return 0


COMMANDS = {"optimize": cmd_optimize, "evaluate": cmd_evaluate, "playback": cmd_playback}


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parser().parse_args(argv)
    import bpy  # lazy: --help and argument errors need no Blender

    ext = ""
    try:
        if args.blend:
            bpy.ops.wm.open_mainfile(filepath=str(Path(args.blend).resolve()))
        ext = ensure_extension(bpy)
        _configure_service(bpy, ext, args)
        _apply_scene_options(ext, bpy.context.scene.render_budget, args)
        return COMMANDS[args.command](bpy, ext, args)
    except Exception as err:  # batch contract: one clear line and a non-zero status
        message = importlib.import_module(f"{ext}.service_process").explain(err) if ext else str(err)
        sys.stderr.write(f"render-budget batch {args.command} failed: {message}\n")
        return 1
    finally:
        if ext:
            importlib.import_module(f"{ext}.service_process").stop_local()
        remove_staged_extension(bpy)


if __name__ == "__main__":
    sys.exit(main())
