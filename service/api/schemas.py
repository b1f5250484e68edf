"""Request and response models, one family per resource (SceneXxx, JobXxx, StoreXxx, RenderXxx).

All inputs are strict at the edge: unknown fields are rejected, numbers must be finite, vectors have fixed
lengths, budgets and sizes are range-checked, so a bad request is a 422 that names the field. Camera
limits come from :mod:`service.store.camera`, the same the camera paths and the renderer use; what JSON
Schema can say (ranges, enums, exactly one of several fields, non-zero vectors) is in the OpenAPI
document too.
"""

from __future__ import annotations

import itertools
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    create_model,
    model_validator,
)

import sim_core
from service import options
from service.camera_path import FPS_MAX, FPS_MIN
from service.params import renderable_space
from service.store.camera import (
    MAX_ASPECT,
    MAX_COORDINATE,
    MAX_RESOLUTION,
    VFOV_MAX,
    VFOV_MIN,
    check_affine,
    check_resolution,
)

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Coordinate = Annotated[float, Field(strict=True, ge=-MAX_COORDINATE, le=MAX_COORDINATE,
                                    allow_inf_nan=False)]
Position = tuple[Coordinate, Coordinate, Coordinate]
_NOT_ZERO = {"not": {"items": {"const": 0}}}
NonZeroVec3 = Annotated[tuple[Finite, Finite, Finite], Field(json_schema_extra=_NOT_ZERO)]
Quaternion = Annotated[tuple[Finite, Finite, Finite, Finite], Field(json_schema_extra=_NOT_ZERO)]
Row4 = tuple[Finite, Finite, Finite, Coordinate]
Zero = Annotated[float, Field(strict=True, ge=0.0, le=0.0)]
One = Annotated[float, Field(strict=True, ge=1.0, le=1.0)]
Matrix4 = tuple[Row4, Row4, Row4, tuple[Zero, Zero, Zero, One]]  # affine: last row [0, 0, 0, 1]
SceneId = Annotated[str, StringConstraints(pattern=r"^[0-9a-f]{64}$")]
Name = Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]{1,64}$")]
Scalar = bool | int | Finite | Annotated[str, StringConstraints(max_length=64)]
Vfov = Annotated[float, Field(strict=True, ge=VFOV_MIN, lt=VFOV_MAX, allow_inf_nan=False,
                              description="vertical field of view, radians")]
Pixels = Annotated[int, Field(strict=True, ge=1, le=MAX_RESOLUTION)]
Fps = Annotated[float, Field(strict=True, ge=FPS_MIN, le=FPS_MAX)]

# Hardware profiles are chosen by name from the bundled list (never a path: nothing is read outside the
# package), and the parameter space's names and values are fixed: the schema lists them.
PROFILES = tuple(sorted(str(p) for p in sim_core.list_profiles()))
Profile = Annotated[str, Field(json_schema_extra={"enum": list(PROFILES)},
                               description="hardware profile (GET /health lists them)")]
_SPACE = {p.name: list(p.values) for p in renderable_space().parameters}


def _known_profile(name: str) -> str:
    if name not in PROFILES:
        raise ValueError(f"unknown hardware profile {name!r}; available: {', '.join(PROFILES)}")
    return name


def _known_parameter(name: str) -> str:
    if name not in _SPACE:
        raise ValueError(f"unknown parameter {name!r}; known: {list(_SPACE)}")
    return name


ProfileName = Annotated[Profile, AfterValidator(_known_profile)]
ParameterName = Annotated[Name, AfterValidator(_known_parameter),
                          Field(json_schema_extra={"enum": list(_SPACE)})]
#: ``{parameter: value}`` of the renderable space (values as a store query returns them). Keys and values
#: are checked against the space where it is built (422 naming the parameter); the schema lists them.
SETTINGS_SCHEMA = {"type": "object", "additionalProperties": False,
                   "properties": {n: {"enum": v} for n, v in _SPACE.items()}}
#: ``{parameter: [values]}``: candidate values per parameter (any of the renderable space's).
SPACE_SCHEMA = {"type": "object", "additionalProperties": False,
                "properties": {n: {"type": "array", "items": {"enum": v}, "minItems": 1, "maxItems": 16}
                               for n, v in _SPACE.items()}}


class StrictModel(BaseModel):
    """Unknown fields are refused; numbers are strict per field (``strict=True``: a bool or a text is not a
    number, as JSON Schema says), while arrays still fill tuples."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def _check_camera_matrix(m: Matrix4, name: str) -> None:
    """Invertible axes (JSON Schema cannot say it; the same test the renderer's camera makes)."""
    check_affine(m, name)


def _not_zero(v: tuple[float, ...], name: str) -> None:
    if not any(v):
        raise ValueError(f"{name} must be non-zero")


def exactly_one(*alternatives: tuple[tuple[str, ...], tuple[str, ...]]) -> dict[str, Any]:
    """JSON Schema for "exactly one of these field combinations": each alternative is (fields that must
    be given, fields that must then be absent or null), as the validators below enforce."""
    return {"oneOf": [{"required": list(given),
                       "properties": {**{f: {"not": {"type": "null"}} for f in given},
                                      **{f: {"type": "null"} for f in absent}}}
                      for given, absent in alternatives]}


# -- scenes --------------------------------------------------------------------------------------------
class ScenePublic(BaseModel):
    id: str = Field(description="SHA-256 of the uploaded .glb bytes")
    size: int
    content_hash: str = Field(description="the simulator's hash of the loaded scene (keys the eval cache)")
    stats: dict[str, Any]
    inert_parameters: dict[str, str] = Field(description="settings that cannot change this scene, and why")
    cameras: int
    created: float


class ScenePage(BaseModel):
    items: list[ScenePublic] = Field(description="newest first")
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last")


# -- camera path and jobs ----------------------------------------------------------------------------------
class CameraFrame(StrictModel):
    """One frame: ``matrix_world``, or ``position`` with ``rotation_quaternion`` (w, x, y, z) or
    ``direction`` (+ optional ``up``, default +Z)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra=exactly_one(
        (("matrix_world",), ("position", "rotation_quaternion", "direction", "up")),
        (("position", "rotation_quaternion"), ("matrix_world", "direction", "up")),
        (("position", "direction"), ("matrix_world", "rotation_quaternion")),
    ))

    time: Annotated[float, Field(strict=True, ge=0.0, le=1e7)]
    matrix_world: Matrix4 | None = None
    position: Position | None = None
    rotation_quaternion: Quaternion | None = None
    direction: NonZeroVec3 | None = None
    up: NonZeroVec3 | None = None
    vfov: Vfov
    resolution: tuple[Pixels, Pixels]

    @model_validator(mode="after")
    def _orientation(self) -> CameraFrame:
        check_resolution(*self.resolution)
        if self.matrix_world is not None:
            if any(v is not None for v in (self.position, self.rotation_quaternion, self.direction, self.up)):
                raise ValueError("give matrix_world or position + orientation, not both")
            _check_camera_matrix(self.matrix_world, "matrix_world")
        elif self.position is None:
            raise ValueError("a frame needs matrix_world or position")
        elif (self.rotation_quaternion is None) == (self.direction is None):
            raise ValueError("position needs exactly one of rotation_quaternion and direction")
        elif self.rotation_quaternion is not None:
            if self.up is not None:
                raise ValueError("up goes with direction, not with rotation_quaternion")
            _not_zero(self.rotation_quaternion, "rotation_quaternion")
        else:
            assert self.direction is not None
            _not_zero(self.direction, "direction")
            if self.up is not None:
                _not_zero(self.up, "up")
        return self


class CameraPathIn(StrictModel):
    """The camera-path JSON (ARCHITECTURE.md): Blender camera matrices, vfov in radians, seconds."""

    version: Literal[1] = 1
    fps: Fps
    frames: Annotated[list[CameraFrame], Field(min_length=1, max_length=20_000)]

    @model_validator(mode="after")
    def _times(self) -> CameraPathIn:
        times = [f.time for f in self.frames]
        if any(b < a for a, b in itertools.pairwise(times)):
            raise ValueError("frame times must not decrease")
        return self


def _option_field(opt: options.Option) -> tuple[Any, Any]:
    """The pydantic type and field of one optimiser option (service.options)."""
    if opt.choices:
        kind: Any = Literal[opt.choices]  # type: ignore[valid-type]
    elif opt.kind in (int, float):
        kind = Annotated[opt.kind, Field(strict=True, ge=opt.minimum, le=opt.maximum, allow_inf_nan=False)]
    else:
        kind = opt.kind
    return (kind | None) if opt.optional else kind, Field(default=opt.default, description=opt.help)


class _JobOptionsBase(StrictModel):
    @model_validator(mode="after")
    def _together(self) -> _JobOptionsBase:
        options.check(self.model_dump(), public_only=True)  # what relates two options (min/max depth)
        return self


#: The optimiser options of a job request, one field per public option of ``service.options`` (same
#: names, defaults, bounds and help); send only those you change.
JobOptionsIn = create_model("JobOptionsIn", __base__=_JobOptionsBase,
                            __doc__="Optimiser options (service.options); omitted ones take their default.",
                            **{o.name: _option_field(o) for o in options.PUBLIC})


class Thresholds(StrictModel):
    """Older spelling of ``options.threshold_power_w`` / ``options.threshold_error`` (still accepted)."""

    power_w: _option_field(options.BY_NAME["threshold_power_w"])[0] | None = None  # type: ignore[valid-type]
    error: _option_field(options.BY_NAME["threshold_error"])[0] | None = None  # type: ignore[valid-type]


_EVAL_PIXELS = Annotated[int, Field(strict=True, ge=options.BY_NAME["eval_height"].minimum,
                                    le=options.BY_NAME["eval_height"].maximum)]


class JobCreate(StrictModel):
    scene_id: SceneId
    camera_path: CameraPathIn
    parameters: Annotated[list[ParameterName], Field(min_length=1, max_length=8)] | None = Field(
        default=None, description="subset of the default parameter space (default: all, minus inert)"
    )
    space: Annotated[dict[str, Annotated[list[Scalar], Field(min_length=1, max_length=16)]],
                     Field(max_length=8, json_schema_extra=SPACE_SCHEMA)] | None = Field(
        default=None, description="candidate values per parameter instead of the default ones (at most 8 "
                                  "parameters: settings pack into 32 bits; any value the schema lists, e.g. "
                                  "shadow_samples 2 or ao_samples 10 between the default steps)"
    )
    options: JobOptionsIn = Field(default_factory=JobOptionsIn)  # type: ignore[valid-type]
    profile: ProfileName = "mobile"
    thresholds: Thresholds | None = Field(
        default=None, description="older spelling of options.threshold_power_w and options.threshold_error")
    resolution: tuple[_EVAL_PIXELS, _EVAL_PIXELS] | None = Field(
        default=None, description="older spelling of [options.eval_width, options.eval_height]")

    @model_validator(mode="after")
    def _older_spellings(self) -> JobCreate:
        """Move ``thresholds`` and ``resolution`` into ``options`` (refusing a disagreement)."""
        moved: dict[str, Any] = {}
        if self.thresholds is not None:
            moved.update({k: v for k, v in (("threshold_power_w", self.thresholds.power_w),
                                            ("threshold_error", self.thresholds.error)) if v is not None})
        if self.resolution is not None:
            moved["eval_width"], moved["eval_height"] = self.resolution
        given = self.options.model_dump(include=self.options.model_fields_set)
        clash = sorted(k for k, v in moved.items() if k in given and given[k] != v)
        if clash:
            raise ValueError(f"options.{clash[0]} disagrees with its older spelling (thresholds/resolution)")
        if moved:
            self.options = JobOptionsIn(**{**given, **moved})
        self.thresholds = self.resolution = None
        return self


class JobProgress(BaseModel):
    model_config = ConfigDict(extra="allow")

    views_done: int = 0
    views_planned: int = 0
    evaluations: int = 0
    cache_hits: int = 0
    elapsed_s: float = 0.0
    estimate_s: float | None = None
    phase: str | None = Field(
        None,
        description="what the job is doing: a search phase (\"root\", \"compare depth N\", \"optimise "
                    "depth N stage M\" for view cubes; \"place samples\", \"optimise path samples\", "
                    "\"refine path samples\", \"price guard frames\" for path samples), \"price at display "
                    "resolution\" while the store's points are priced at the path's resolution, then "
                    "\"done\" (or \"cancelled\"); free text for people, not an enumeration to branch on; "
                    "null before the first report")
    fraction: float | None = Field(
        None, ge=0.0, le=1.0,
        description="the share of the whole job done, the search and the display pricing after it (in "
                    "search steps, a priced camera weighted by its cost): never decreasing over the job's "
                    "attempts, 1 only when done; null before the first report and for jobs run by "
                    "versions without it")


class JobPublic(BaseModel):
    id: str
    scene_id: str
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    progress: JobProgress
    error: str | None
    store_id: str | None
    cancel_requested: bool
    attempts: int
    created: float
    started: float | None
    finished: float | None


class JobPage(BaseModel):
    items: list[JobPublic] = Field(description="newest first")
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last")


# -- stores ------------------------------------------------------------------------------------------
class StorePublic(BaseModel):
    id: str
    scene_id: str
    job_id: str = Field(description="the job that made it first (equal stores share one id)")
    size: int = Field(description="bytes of the store JSON")
    created: float


class StorePage(BaseModel):
    items: list[StorePublic] = Field(description="newest first")
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last")


class PreviousSettings(StrictModel):
    """The settings shown when the target changed and how long ago that was, for the temporal filter
    (Eq. 8's pace along the frontier: :mod:`service.store.temporal`)."""

    indices: Annotated[list[Annotated[int, Field(strict=True, ge=0, le=15)]],
                       Field(min_length=1, max_length=8)]
    elapsed_s: Annotated[float, Field(strict=True, ge=0.0, le=1e7)]
    period_s: Annotated[float, Field(strict=True, gt=0.0, le=3600.0)] = 2.0


#: The store lookup's query options (``service.options.QUERY_OPTIONS``: the frame-rate target ``fps``,
#: the ``priority``, the ``error_margin`` and the ``power_margin``), one field each with the schema's
#: default, bounds and help: the query and verify requests take them; old requests without them get the
#: defaults.
QueryOptionsIn = create_model("QueryOptionsIn", __base__=StrictModel,
                              __doc__="The lookup's query options (service.options.QUERY_OPTIONS).",
                              **{o.name: _option_field(o) for o in options.QUERY_OPTIONS})


class StoreQuery(QueryOptionsIn):  # type: ignore[valid-type,misc]
    # "Exactly one budget" and "exactly one orientation" in the OpenAPI too, for clients and fuzzers.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra={"allOf": [
        exactly_one((("power_budget_w",), ("error_budget",)), (("error_budget",), ("power_budget_w",))),
        exactly_one((("direction",), ("matrix",)), (("matrix",), ("direction",))),
    ]})

    position: Position
    direction: NonZeroVec3 | None = Field(default=None, description="view direction (or give matrix)")
    matrix: Matrix4 | None = Field(default=None, description="camera world matrix, looks down local -Z")
    fov: Vfov | None = None
    aspect: Annotated[float, Field(strict=True, ge=1.0 / MAX_ASPECT, le=MAX_ASPECT)] | None = Field(
        default=None, description="width / height (default: the store's)")
    power_budget_w: Annotated[float, Field(strict=True, gt=0.0, le=1e4)] | None = None
    error_budget: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] | None = None
    previous: PreviousSettings | None = None

    @model_validator(mode="after")
    def _one_budget(self) -> StoreQuery:
        if (self.power_budget_w is None) == (self.error_budget is None):
            raise ValueError("give exactly one of power_budget_w and error_budget")
        if (self.direction is None) == (self.matrix is None):
            raise ValueError("give exactly one of direction and matrix")
        if self.direction is not None:
            _not_zero(self.direction, "direction")
        if self.matrix is not None:
            _check_camera_matrix(self.matrix, "matrix")
        return self


class QueryResult(BaseModel):
    settings: dict[str, Any]
    indices: list[int]
    packed: int
    power_w: float = Field(description="predicted power of the returned settings (a point of the view's "
                                       "frontier, also when filtered) at the frame rate they reach")
    error: float = Field(description="predicted error of the returned settings")
    clamped: bool
    infeasible: bool
    filtered: bool = Field(description="indices come from the temporal filter, not the raw target")
    target_indices: list[int] = Field(description="the lookup's target before the temporal filter")
    frame_time_s: float | None = Field(
        default=None, description="predicted frame time of the returned settings: at this camera where the "
                                  "store keeps frame times per pricing camera (interpolated as "
                                  "expected_power_w), else the worst over those cameras (null: the store "
                                  "predates frame times)")
    fps: float | None = Field(default=None, description="the frame rate the returned settings reach: "
                                                        "fps_target when they keep up, else 1 / frame_time_s")
    fps_target: float = Field(description="the frame rate asked for (the query's fps, else the store's: what "
                                          "its power was priced for)")
    meets_fps: bool | None = Field(
        default=None, description="the returned settings keep up with fps_target (by frame_time_s); false "
                                  "only when no setting of this view does, or (priority budget) none within "
                                  "the budget does (null: unknown)")
    priority: str = Field(default="frame_rate", description="the query's priority, as the lookup applied it")
    error_margin: float = Field(default=0.0, description="how far under an error budget the lookup kept the "
                                                         "stored error (the query's; 0 for a power budget): "
                                                         "infeasible then says nothing lies under budget "
                                                         "less margin")
    power_margin: float = Field(default=0.0, description="what share of a power budget the lookup kept the "
                                                         "stored power under (the query's; 0 for an error "
                                                         "budget): infeasible then says nothing lies under "
                                                         "budget less that share")
    expected_power_w: float | None = Field(
        default=None, description="predicted power of the returned settings at this camera: their figures at "
                                  "the cameras the view's frontier was priced at, interpolated here (power_w "
                                  "is the worst of those, what the budget was checked against)")
    expected_error: float | None = Field(default=None, description="predicted error at this camera, likewise")
    figures_resolution: list[int] | None = Field(
        default=None, description="[width, height] the store's error, power and frame-time figures were "
                                  "measured at (null: the store does not say): with figures_kind display "
                                  "they hold for a display of that size, not for a larger render")
    figures_kind: Literal["display", "preview", "unknown"] = Field(
        default="unknown", description="display: priced at that display size; preview: the search's small "
                                       "renders, power scaled by the pixel count (not a display figure); "
                                       "unknown: the store does not say")


# -- render and evaluate -----------------------------------------------------------------------------
class CameraIn(StrictModel):
    matrix_world: Matrix4
    vfov: Vfov
    width: Annotated[int, Field(strict=True, ge=8, le=4096)]
    height: Annotated[int, Field(strict=True, ge=8, le=4096)]

    @model_validator(mode="after")
    def _camera(self) -> CameraIn:
        _check_camera_matrix(self.matrix_world, "matrix_world")
        check_resolution(self.width, self.height)
        return self


class RenderRequest(StrictModel):
    scene_id: SceneId
    camera: CameraIn
    settings: Annotated[dict[str, Scalar], Field(json_schema_extra=SETTINGS_SCHEMA)] | None = Field(
        default=None, description="parameter -> value (as a store query returns them); others at max quality"
    )
    profile: ProfileName = "mobile"
    fps: Fps = 30.0
    format: Literal["png", "exr"] = "png"


class RenderResponse(BaseModel):
    format: Literal["png", "exr"]
    media_type: str
    width: int
    height: int
    image_base64: str
    counters: dict[str, int]
    energy: dict[str, Any]
    render_time_s: float


PixelCount = Annotated[int, Field(ge=1, le=16384)]


class EvaluateRequest(StrictModel):
    scene_id: SceneId
    camera: CameraIn
    settings: Annotated[dict[str, Scalar], Field(json_schema_extra=SETTINGS_SCHEMA)] | None = None
    profile: ProfileName = "mobile"
    fps: Fps = 30.0
    power_resolution: tuple[PixelCount, PixelCount] | None = (
        Field(default=None, description="[width, height] to report power and frame time for (static power "
                                        "plus dynamic power scaled by the pixel count, as a store predicts "
                                        "it); default: the camera's own size"))


class EvaluateResponse(BaseModel):
    error: float
    power_w: float = Field(description="drawn at the frame rate reached (never above the full-speed power)")
    frame_time_s: float
    fps: float = Field(description="the frame rate reached: fps_target when the frame keeps up, else "
                                   "1 / frame_time_s")
    fps_target: float = Field(description="the frame rate asked for (the request's fps)")
    deadline_met: bool = Field(description="frame_time_s <= 1 / fps_target")
    breakdown: dict[str, Any]


# -- verify ------------------------------------------------------------------------------------------
class VerifyRequest(QueryOptionsIn):  # type: ignore[valid-type,misc]
    """Render a sample of the path's frames with the store's settings and measure them (service.verify)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra=exactly_one(
        (("power_budget_w",), ("error_budget",)), (("error_budget",), ("power_budget_w",))))

    camera_path: CameraPathIn
    power_budget_w: Annotated[float, Field(strict=True, gt=0.0, le=1e4)] | None = None
    error_budget: Annotated[float, Field(strict=True, gt=0.0, le=1.0)] | None = None
    frames: Annotated[int, Field(strict=True, ge=1, le=32)] = Field(
        default=8, description="path frames to render, spread evenly over the path")
    resolution: tuple[PixelCount, PixelCount] | None = Field(
        default=None, description="[width, height] to render at; default: each frame's own resolution")

    @model_validator(mode="after")
    def _one_budget(self) -> VerifyRequest:
        if (self.power_budget_w is None) == (self.error_budget is None):
            raise ValueError("give exactly one of power_budget_w and error_budget")
        if self.resolution is not None:
            check_resolution(*self.resolution)
        return self


class VerifyResult(BaseModel):
    budget_mode: Literal["error", "power"]
    budget_value: float
    resolution: list[int]
    profile: str
    fps: float = Field(description="the frame rate the settings were looked up and measured for (the "
                                   "request's fps, else the store's)")
    priority: str = Field(default="frame_rate", description="the lookup's priority")
    error_margin: float = Field(default=0.0, description="the lookup's error margin (error budgets; frames "
                                                         "are within budget against the budget itself)")
    power_margin: float = Field(default=0.0, description="the lookup's power margin (power budgets; frames "
                                                         "are within budget against the budget itself)")
    store_figures_resolution: list[int] | None = Field(
        description="where the store says its figures were measured (its meta)")
    store_figures_kind: Literal["display", "preview", "unknown"] = Field(
        default="unknown", description="display: the figures hold for a display of that size; preview: the "
                                       "search's renders at that size, power scaled by the pixel count; "
                                       "unknown: the store does not say")
    summary: dict[str, Any]
    frames: list[dict[str, Any]]


# -- health ------------------------------------------------------------------------------------------
class Health(BaseModel):
    status: Literal["ok"]
    version: str
    profiles: list[str]
    executor: str
    jobs: dict[str, int]
