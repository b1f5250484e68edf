"""The optimiser's options, declared once: name, type, default, bounds, help, and where each is shown.

Every layer derives its view from :data:`OPTIONS`: the ``render-budget optimize`` arguments
(:func:`add_arguments`), the REST job request (``service.api.schemas.JobOptionsIn``), the add-on's
scene properties and panel (``addon/properties.py``, ``addon/panels.py``), the add-on's job request
(``addon.core.job_runner.JobRequest``), the batch ``optimize`` arguments (``addon/batch.py``) and the
run configuration (``service.optimize.OptimizeConfig``). Clients send only the options they
override; the service fills in the defaults declared here and keeps the full set with the job.

Stdlib only: the Blender add-on carries this module (it runs inside Blender's own Python).

Adding an option: append an :class:`Option` to :data:`OPTIONS` and read it in ``service.optimize``
(``config.<name>``); every layer picks it up, and ``tests/test_options.py`` walks it through them.
"""

from __future__ import annotations

import argparse
import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: Camera-sample strategies of the octree builder (``service.octree``).
VIEW_SAMPLING = ("path", "aimed", "axis")
#: Image-error measures of the evaluator (``service.evaluation``).
METRICS = ("ssim", "ssim_gaussian", "flip")
#: How a store's figures are priced at the path's resolution (``service.display_pricing``), or
#: "preview": the search's own figures at the evaluation resolution, labelled so.
DISPLAY_ESTIMATORS = ("tiles", "full", "preview")


@dataclass(frozen=True)
class Option:
    """One optimiser option.

    ``optional``: ``None`` is a value meaning "derive it" (the help says from what); where a layer
    cannot hold ``None`` (a Blender integer property) it shows 0, and on a command line
    ``derived_word`` spells it (``--fps store``, ``--eval-width auto``, ``--display-height path``), so a
    value saved earlier can be set back to the derived one (the add-on's batch over a .blend). Every
    optional option has one. ``public``: offered by the CLI, the
    REST job request, the add-on and batch; internal options are set by library callers only.
    ``group`` and ``modes`` lay out the add-on panel: the box an option sits in, and the
    ``view_sampling`` values it applies to (greyed out for the others)."""

    name: str
    kind: type  # bool, int, float or str
    default: Any
    label: str
    help: str
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] = ()
    choice_labels: tuple[str, ...] = ()  # what the add-on shows for each choice
    optional: bool = False
    public: bool = True
    flag: str = ""  # command-line spelling, when not the name with dashes
    aliases: tuple[str, ...] = ()  # older command-line spellings still accepted
    metavar: str | None = None
    derived_word: str = ""  # optional options: the command-line word for None, "derive it"
    group: str = "Optimiser"
    modes: tuple[str, ...] = ()  # view_sampling values this option matters for (empty: all)
    soft_max: float | None = None  # the add-on's slider range, when narrower than ``maximum``
    precision: int | None = None  # digits the add-on shows

    @property
    def cli_flag(self) -> str:
        return "--" + (self.flag or self.name.replace("_", "-"))

    def check(self, value: Any) -> Any:
        """``value`` as this option's type, or ValueError naming the option and its bounds."""
        if value is None:
            if self.optional:
                return None
            raise ValueError(f"{self.name} must be given (it has no derived default)")
        if self.kind is bool:
            if not isinstance(value, bool):
                raise ValueError(f"{self.name} must be true or false, got {value!r}")
            return value
        if self.kind is str:
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise ValueError(f"{self.name} must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if isinstance(value, bool):
            raise ValueError(f"{self.name} must be a number, got {value!r}")
        if self.kind is int:
            try:
                v: float = operator.index(value)
            except TypeError:
                raise ValueError(f"{self.name} must be a whole number, got {value!r}") from None
        else:
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{self.name} must be a number, got {value!r}") from None
            if not math.isfinite(v):
                raise ValueError(f"{self.name} must be finite, got {value!r}")
        if (self.minimum is not None and v < self.minimum) or (self.maximum is not None and v > self.maximum):
            raise ValueError(f"{self.name} must be in {self.bounds_text()}, got {value!r}")
        return v

    def bounds_text(self) -> str:
        lo = "-inf" if self.minimum is None else f"{self.minimum:g}"
        hi = "inf" if self.maximum is None else f"{self.maximum:g}"
        return f"[{lo}, {hi}]"


_SAMPLES = "Camera samples"
_CUBES = ("aimed", "axis")

OPTIONS: tuple[Option, ...] = (
    Option("view_sampling", str, "path", "Camera samples",
           "camera samples: the path's own cameras on a lattice refined by viewing distance (path), or "
           "the paper's six views per corner with frontier-difference refinement, aimed at what the "
           "path sees (aimed) or along the world axes (axis)",
           choices=VIEW_SAMPLING, choice_labels=("Path cameras", "Aimed view cubes", "Axis view cubes"),
           aliases=("camera-sampling",), group=_SAMPLES),
    Option("max_depth", int, 6, "Max depth",
           "deepest octree level (path cameras: caps the refinement; view cubes: the split depth, keep "
           "it at 1-3)", minimum=0, maximum=8, metavar="N", group=_SAMPLES),
    Option("min_depth", int, 0, "Min depth",
           "split the nodes the path passes through at least this deep (0: only where needed)",
           minimum=0, maximum=8, metavar="N", group=_SAMPLES),
    Option("path_resolution", float, 0.25, "Path resolution",
           "path cameras: octree leaves at most this times the viewing distance wide",
           minimum=0.01, maximum=10.0, metavar="R", group=_SAMPLES, modes=("path",), precision=3),
    Option("guard_frames", int, 2, "Guard frames",
           "path cameras: also price each frontier at this many more path cameras (and at one camera of "
           "as many other passes of the path through it), keeping the worst error and power",
           minimum=0, maximum=8, metavar="N", group=_SAMPLES, modes=("path",)),
    Option("guard_radius", float, 0.01, "Guard radius",
           "path cameras with guard frames: then price each frontier at the frame of its group least like "
           "its pricing cameras while that frame is more than this camera dissimilarity from all of them "
           "(squared eye offset over the viewing distance squared plus squared view-direction difference; "
           "0.01 is about 6 degrees, 0.05 about 13), at most guard frames more (0: off)",
           minimum=0.0, maximum=4.0, metavar="D", group=_SAMPLES, modes=("path",), soft_max=0.5,
           precision=3),
    Option("threshold_power_w", float, 0.05, "Power threshold (W)",
           "view cubes: subdivide where neighbouring frontiers differ by more than this many watts",
           minimum=1e-4, maximum=1e4, flag="threshold-power", metavar="W", group=_SAMPLES, modes=_CUBES,
           soft_max=5.0, precision=3),
    Option("threshold_error", float, 0.01, "Error threshold",
           "view cubes: subdivide where neighbouring frontiers differ by more than this error",
           minimum=1e-5, maximum=1.0, metavar="E", group=_SAMPLES, modes=_CUBES, precision=4),
    Option("population", int, 24, "Population", "NSGA-II population of each camera sample's search",
           minimum=4, maximum=512, metavar="N"),
    Option("generations", int, 25, "Generations", "NSGA-II generations of each full search",
           minimum=1, maximum=500, metavar="N"),
    Option("descent_steps", int, 8, "Descent steps",
           "after each camera's search, where max quality misses the frame rate, step down from it one "
           "parameter one value at a time, each step the one that saves the most frame time for the error "
           "it adds, at most this many steps or until it keeps up (0: none; a few dozen small renders a "
           "camera; the real-time end is priced where the real-time points priced stay over error 0.02)",
           minimum=0, maximum=32, metavar="N"),
    Option("seed", int, 0, "Seed", "random seed (the same seed gives the same store)",
           minimum=0, maximum=2**31 - 1, metavar="N"),
    Option("exhaustive_limit", int, 512, "Exhaustive up to",
           "enumerate every setting instead of searching when the space has at most this many",
           minimum=0, maximum=65536, metavar="N"),
    Option("metric", str, "ssim", "Error metric",
           "image error against the maximum-quality render: 1 - SSIM (box or Gaussian window) or FLIP",
           choices=METRICS, choice_labels=("1 - SSIM", "1 - SSIM (Gaussian window)", "FLIP")),
    Option("eval_width", int, None, "Evaluation width",
           "evaluation image width in pixels (default: from the path's aspect ratio)",
           minimum=8, maximum=1024, optional=True, metavar="PX", derived_word="auto", group="Evaluation"),
    Option("eval_height", int, 36, "Evaluation height", "evaluation image height in pixels",
           minimum=8, maximum=1024, metavar="PX", group="Evaluation"),
    Option("display_estimator", str, "tiles", "Store figures",
           "how every point the store records is priced at the path's own resolution: a tile estimator "
           "(a sample of the frame traced at that resolution; displays smaller than 1280x720 are priced "
           "as whole frames all the same), whole frames (exact, slow), or preview "
           "(the search's small images, power scaled by the pixel ratio: a rough preview only)",
           choices=DISPLAY_ESTIMATORS,
           choice_labels=("Tile estimator", "Whole frames", "Preview resolution only"),
           group="Evaluation"),
    Option("display_fraction", float, 0.25, "Traced share",
           "tile estimator: share of the frame's blocks traced at the path's resolution",
           minimum=0.01, maximum=1.0, metavar="F", group="Evaluation", precision=2),
    Option("display_points", int, 8, "Points priced",
           "at most this many points of each frontier's settings that keep up with the frame rate, spread "
           "along their tier (both ends kept), are priced at the path's resolution and kept in the store "
           "(0: all; each costs a share of a full-size frame at every camera the frontier is priced at; "
           "the settings that miss the rate: slow points)", minimum=0, maximum=64, metavar="N",
           group="Evaluation"),
    Option("slow_points", int, 8, "Slow points priced",
           "at most this many of each frontier's settings that miss the frame rate (slower and more "
           "accurate than every real-time one; a lookup reads them only when its priority is the budget), "
           "spread along their tier (both ends kept), are priced at the path's resolution and kept in the "
           "store (0: all; 1: max quality alone, which each camera's reference render prices at no extra "
           "cost; each other point costs about a max-quality frame at every camera the frontier is priced "
           "at)", minimum=0, maximum=64, metavar="N", group="Evaluation"),
    Option("bridge_points", int, 8, "Bridging points priced",
           "at most this many more settings of each frontier are priced at the path's resolution where "
           "the priced real-time points' errors jump (more than doubling from one to the next): the "
           "cheaper point with one parameter of the dearer one, a few rounds (a search at small images "
           "misjudges some settings' error at full size; 0: none)", minimum=0, maximum=64, metavar="N",
           group="Evaluation"),
    Option("display_height", int, None, "Display height",
           "price the store's figures at this height (width from the path's aspect) instead of the path's "
           "own resolution: a stated smaller display size when full size is too slow (default: the path's "
           "own resolution)", minimum=16, maximum=4320, optional=True, metavar="PX", derived_word="path",
           group="Evaluation"),
    # internal: set by library callers (tests, benchmarks), not offered by the CLI, REST or add-on
    Option("margin", float, 0.1, "Margin", "view cubes: fraction of a node's side added around it when "
           "testing whether the path passes through it", minimum=0.0, public=False),
    Option("pad_fraction", float, 0.1, "Padding", "root cube padding, as a fraction of the path's extent",
           minimum=0.0, public=False),
    Option("min_size", float, 1.0, "Minimum size", "smallest root cube side (metres)", minimum=1e-6,
           public=False),
    Option("skip_inert", bool, True, "Skip inert", "leave out the parameters the simulator reports "
           "cannot change this scene", public=False),
    Option("display_tiles_min_pixels", int, 1280 * 720, "Tile estimator from",
           "the tile estimator prices display sizes of at least this many pixels; smaller ones are priced "
           "as whole frames (up to 640x360 the blocks' SSIM margins and whole adaptive tiles make a "
           "quarter of the blocks cost about as much as the frame, and the estimate's error, 0.0017 low "
           "at the setting the error budget picked, broke the valley's budget at 640x360: "
           "bench/RESULTS.md)", minimum=0, public=False),
    Option("power_at_path_resolution", bool, True, "Search power at path resolution",
           "the search compares the evaluation images' power scaled to the path's pixel count (static "
           "power would hide every difference at a few hundred pixels); a search figure, never a "
           "store's unless display_estimator is preview", public=False),
)

#: The store lookup's frame-rate target (not an optimiser option: a query's): declared here so that the
#: lookup (``ParetoStore.lookup``), ``render-budget query --fps``, ``POST /stores/{id}/query``'s ``fps``
#: and the add-on's playback property share its bounds and help.
FPS_MIN, FPS_MAX = 0.01, 1000.0  # the frame rates a camera path or a store query may have
QUERY_FPS = Option("fps", float, None, "Frame rate",
                   "frame rate the chosen settings must keep up with (default: the store's own, what its "
                   "power was priced for); power is predicted at the rate each setting reaches, and a "
                   "setting that misses the rate is never chosen while one that meets it exists (unless the "
                   "priority is the budget and none within the budget does)",
                   minimum=FPS_MIN, maximum=FPS_MAX, optional=True, metavar="FPS", derived_word="store",
                   group="Playback")

#: What a lookup keeps when no stored setting keeps both the budget and the frame rate (a query option,
#: declared here for the same reason as :data:`QUERY_FPS`): "frame_rate" (the issue's rule: a setting
#: that misses the rate is never chosen while one that meets it exists, so the budget gives way) or
#: "budget" (the settings within the budget first, those that keep up preferred among them, so the frame
#: rate gives way and the lookup says so).
PRIORITIES = ("frame_rate", "budget")
QUERY_PRIORITY = Option("priority", str, "frame_rate", "Priority",
                        "when no setting keeps both the budget and the frame rate: keep the frame rate "
                        "(the budget is broken) or keep the budget (the frame rate is missed)",
                        choices=PRIORITIES, choice_labels=("Frame rate first", "Budget first"),
                        group="Playback")

#: How far under an error budget a lookup keeps the store's error (a query option, declared here for the
#: same reason as :data:`QUERY_FPS`): room for what the prediction itself gets wrong (the frames between
#: pricing cameras, the tile estimator's sampling), which ``render-budget verify`` measures. Error budgets
#: only; a budget is still kept or broken against its own value.
QUERY_ERROR_MARGIN = Option("error_margin", float, 0.0, "Error margin",
                            "error budgets: choose among the settings predicted at least this far under the "
                            "budget (1 - SSIM; room for the prediction's own error, which verify measures); "
                            "when none is, the most accurate setting of the tier, as when none keeps the "
                            "budget", minimum=0.0, maximum=0.5, metavar="E", group="Playback", soft_max=0.01,
                            precision=4)

#: How far under a power budget a lookup keeps the store's power, as a fraction of the budget (a query
#: option, declared here for the same reason as :data:`QUERY_FPS`): room for the power prediction's own
#: error near the budget (the lab's 1280x720 picks predicted 1-2 % under a budget measured up to 4.5 %
#: over it: bench/RESULTS.md). Power budgets only; a budget is still kept or broken against its own value.
QUERY_POWER_MARGIN = Option("power_margin", float, 0.0, "Power margin",
                            "power budgets: choose among the settings predicted to draw at least this "
                            "fraction under the budget (0.05: at most 95 percent of it; room for the "
                            "prediction's own error, which verify measures); when none does, the cheapest "
                            "setting of the tier, as when none keeps the budget", minimum=0.0, maximum=0.5,
                            metavar="F",
                            group="Playback", soft_max=0.1, precision=3)

#: The store lookup's query options (not the optimiser's): every layer that looks a store up (CLI query
#: and verify, REST query and verify, the add-on's playback, engine and Evaluate Path, the main job)
#: offers these, built from these declarations as the optimiser's options are from :data:`OPTIONS`.
QUERY_OPTIONS: tuple[Option, ...] = (QUERY_FPS, QUERY_PRIORITY, QUERY_ERROR_MARGIN, QUERY_POWER_MARGIN)
QUERY_BY_NAME: dict[str, Option] = {o.name: o for o in QUERY_OPTIONS}
#: How each priority reads in a report or a command's output ("Frame rate first", "Budget first").
PRIORITY_LABELS: dict[str, str] = dict(zip(PRIORITIES, QUERY_PRIORITY.choice_labels, strict=True))


#: Seconds a running optimisation job may go without progress before a command-line client gives it up.
#: A job reports each view searched and each camera priced (minutes at most, even at 1280x720), while a
#: heavy scene's whole job takes hours: a bound on the total time stopped healthy jobs.
JOB_STALL_TIMEOUT_S = 1800.0


def positive_number(text: str) -> float:
    """A command-line number that must be positive and finite (a rate, a budget, a timeout)."""
    v = float(text)
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def check_query(values: Mapping[str, Any]) -> dict[str, Any]:
    """Every query option (:data:`QUERY_OPTIONS`): the defaults with ``values`` (validated, unknown names
    refused) on top, as keyword arguments of ``ParetoStore.lookup``."""
    unknown = sorted(set(values) - set(QUERY_BY_NAME))
    if unknown:
        raise ValueError(f"unknown query options {unknown}; known: {sorted(QUERY_BY_NAME)}")
    return {name: o.check(values.get(name, o.default)) for name, o in QUERY_BY_NAME.items()}


def query_from_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The query options of a command line built with :func:`add_argument` for each of
    :data:`QUERY_OPTIONS` (``--fps``, ``--priority``, ``--error-margin``, ``--power-margin``), checked,
    as lookup keywords."""
    return check_query(query_fields(args))


def query_fields(source: Mapping[str, Any] | object) -> dict[str, Any]:
    """The query options a request carries (a JSON payload, a REST body, a command line's arguments),
    unchecked, leaving out the rest: what passes them on to a lookup without naming each one."""
    if isinstance(source, Mapping):
        return {name: source[name] for name in QUERY_BY_NAME if name in source}
    return {name: getattr(source, name) for name in QUERY_BY_NAME if hasattr(source, name)}


def only_query_overrides(values: Mapping[str, Any]) -> dict[str, Any]:
    """The query options that differ from their default (what a client sends: a service from before an
    option accepts a request that leaves it out)."""
    return {k: v for k, v in check_query(values).items() if v != QUERY_BY_NAME[k].default}


BY_NAME: dict[str, Option] = {o.name: o for o in OPTIONS}
PUBLIC: tuple[Option, ...] = tuple(o for o in OPTIONS if o.public)
GROUPS: tuple[str, ...] = tuple(dict.fromkeys(o.group for o in PUBLIC))


def defaults() -> dict[str, Any]:
    """Every option at its default."""
    return {o.name: o.default for o in OPTIONS}


def check(values: Mapping[str, Any], *, public_only: bool = False) -> dict[str, Any]:
    """Validated copy of some option values (unknown names refused); also checks what relates two
    options (``min_depth <= max_depth``, with the defaults standing in for options not given)."""
    known = {o.name for o in PUBLIC} if public_only else set(BY_NAME)
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown optimiser options {unknown}; known: {sorted(known)}")
    out = {name: BY_NAME[name].check(v) for name, v in values.items()}
    lo = out.get("min_depth", BY_NAME["min_depth"].default)
    hi = out.get("max_depth", BY_NAME["max_depth"].default)
    if lo > hi:
        raise ValueError(f"min_depth ({lo}) must not exceed max_depth ({hi})")
    return out


def resolve(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Every option: the defaults with ``overrides`` (validated) on top."""
    return {**defaults(), **check(overrides)}


def eval_resolution(eval_width: int | None, eval_height: int, aspect: float) -> tuple[int, int]:
    """The evaluation image size: ``eval_width`` or, when it is None, the height times the path's
    aspect (at least 8 pixels)."""
    height = int(eval_height)
    return (int(eval_width) if eval_width is not None else max(8, round(height * aspect))), height


# -- command lines (render-budget optimize; the add-on's batch optimize) ---------------------------------

class _Derive:
    """The type of :data:`DERIVE`."""

    def __repr__(self) -> str:
        return "DERIVE"


#: What an option's ``derived_word`` parses to on a command line whose options are overrides
#: (``with_default=False``: None there means "not given, keep the value set earlier"): set the option
#: back to None, "derive it" (the add-on's batch ``--fps store``: the store's own frame rate again;
#: ``--eval-width auto``: from the path's aspect; ``--display-height path``: the path's own resolution).
DERIVE = _Derive()


def _arg_type(opt: Option, derived: Any = None) -> Any:
    """Parse and check one option's text; its ``derived_word`` becomes ``derived`` (None, or
    :data:`DERIVE` where None means "not given")."""
    def parse(text: str) -> Any:
        if opt.derived_word and text == opt.derived_word:
            return derived
        try:
            value: Any = int(text) if opt.kind is int else float(text) if opt.kind is float else text
            return opt.check(value)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{opt.name} ")) from None

    parse.__name__ = opt.kind.__name__  # argparse names the type in its messages
    return parse


def add_arguments(parser: argparse.ArgumentParser | Any, *, with_defaults: bool = True,
                  left_out: str = "the value set earlier stays") -> None:
    """One argument per public option (``dest`` = the option name). ``with_defaults=False`` leaves
    every default None, so the caller can tell which options were given (overrides only); ``left_out``
    then says in the help what an option left out keeps."""
    for o in PUBLIC:
        add_argument(parser, o, with_default=with_defaults, left_out=left_out)


def add_argument(parser: argparse.ArgumentParser | Any, opt: Option, *, with_default: bool = True,
                 left_out: str = "the value set earlier stays") -> None:
    """The command-line argument of one option (``dest`` = its name), validated by :meth:`Option.check`."""
    default = opt.default if with_default else None
    shown = "" if opt.default is None else f" (default {opt.default})"  # optional: the help says it
    metavar = opt.metavar
    if opt.derived_word:
        metavar = f"{opt.metavar or opt.kind.__name__.upper()}|{opt.derived_word}"
        shown += (f" ({opt.derived_word}: that default, as when left out)" if with_default else
                  f" (left out: {left_out}; {opt.derived_word}: back to that default)")
    parser.add_argument(opt.cli_flag, *(f"--{a}" for a in opt.aliases), dest=opt.name, default=default,
                        type=None if opt.choices else _arg_type(opt, None if with_default else DERIVE),
                        choices=opt.choices or None, metavar=metavar, help=opt.help + shown)


def from_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The public options given on a command line parsed with ``with_defaults=False`` (None = not
    given), or all of them with ``with_defaults=True``; validated together."""
    given = {o.name: getattr(args, o.name) for o in PUBLIC if getattr(args, o.name, None) is not None}
    return check({k: None if v is DERIVE else v for k, v in given.items()}, public_only=True)


def only_overrides(values: Mapping[str, Any]) -> dict[str, Any]:
    """The values that differ from their default (what a client sends)."""
    return {k: v for k, v in check(values).items() if v != BY_NAME[k].default}
