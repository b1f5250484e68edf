"""The declarative search space: parameters, their ordered values, and how they map to RenderSettings.

A parameter has a name, values ordered from cheapest to best (or the other way: ``max_quality`` says
which index is the best), and for every value the ``sim_core.RenderSettings`` fields it sets. A
settings vector is one value index per parameter, packed 4 bits per parameter into a 32-bit integer
by :mod:`service.store` (the one packing implementation). Parameters found inert for a scene
(``sim_core.inert_parameters``) are *fixed* at their maximum-quality value: they stay in the packed
vector, so stores from different scenes read alike, but the search skips them.

Adding a parameter: add a row to :func:`renderable_space` with the RenderSettings fields of each value,
and its default values to :data:`DEFAULT_VALUES`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import sim_core
from service.store import (
    MAX_PARAMS,
    MAX_VALUES_PER_PARAM,
    StoredParameter,
    pack_indices,
    unpack_indices,
)

Indices = tuple[int, ...]


@dataclass(frozen=True)
class Parameter:
    """One search dimension. ``fields[i]`` are the RenderSettings keyword values for value ``i``
    (default: ``{name: values[i]}``)."""

    name: str
    values: tuple[Any, ...]
    max_quality: int
    fields: tuple[Mapping[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("parameter needs a name")
        vals = tuple(self.values)
        if not 1 <= len(vals) <= MAX_VALUES_PER_PARAM:
            raise ValueError(f"parameter {self.name!r}: 1..{MAX_VALUES_PER_PARAM} values, got {len(vals)}")
        if len(set(map(repr, vals))) != len(vals):
            raise ValueError(f"parameter {self.name!r}: duplicate values")
        mq = self.max_quality
        if not 0 <= mq < len(vals):
            raise ValueError(f"parameter {self.name!r}: max_quality index {mq} out of range")
        flds = tuple(dict(f) for f in self.fields) or tuple({self.name: v} for v in vals)
        if len(flds) != len(vals):
            raise ValueError(f"parameter {self.name!r}: one fields mapping per value")
        object.__setattr__(self, "values", vals)
        object.__setattr__(self, "fields", flds)

    @property
    def field_names(self) -> tuple[str, ...]:
        return tuple(sorted({k for f in self.fields for k in f}))


@dataclass(frozen=True)
class ParameterSpace:
    """Ordered parameters (at most 8, 16 values each) plus the ones fixed for a scene (name -> index)."""

    parameters: tuple[Parameter, ...]
    fixed: Mapping[str, int] = field(default_factory=dict)
    fixed_reasons: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        params = tuple(self.parameters)
        if not 1 <= len(params) <= MAX_PARAMS:
            raise ValueError(f"a space has 1..{MAX_PARAMS} parameters, got {len(params)}")
        names = [p.name for p in params]
        if len(set(names)) != len(names):
            raise ValueError("parameter names must be unique")
        fixed = {str(k): int(v) for k, v in dict(self.fixed).items()}
        by = {p.name: p for p in params}
        for k, v in fixed.items():
            if k not in by or not 0 <= v < len(by[k].values):
                raise ValueError(f"fixed parameter {k!r}={v} is not in the space")
        object.__setattr__(self, "parameters", params)
        object.__setattr__(self, "fixed", fixed)
        object.__setattr__(self, "fixed_reasons", dict(self.fixed_reasons))

    # -- shape --------------------------------------------------------------------------------------

    @classmethod
    def default(cls) -> ParameterSpace:
        return default_space()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def free_positions(self) -> tuple[int, ...]:
        return tuple(i for i, p in enumerate(self.parameters) if p.name not in self.fixed)

    @property
    def free_n_values(self) -> tuple[int, ...]:
        return tuple(len(self.parameters[i].values) for i in self.free_positions)

    @property
    def size(self) -> int:
        """Number of settings the search can reach (fixed parameters count once)."""
        return math.prod(self.free_n_values)

    def max_quality_indices(self) -> Indices:
        return tuple(self.fixed.get(p.name, p.max_quality) for p in self.parameters)

    def min_quality_indices(self) -> Indices:
        """The other end of every free parameter (the cheapest setting when values are ordered)."""
        return tuple(self.fixed.get(p.name, 0 if p.max_quality == len(p.values) - 1 else len(p.values) - 1)
                     for p in self.parameters)

    def expand(self, free: Sequence[int]) -> Indices:
        """Full index vector from the free parameters' indices (fixed ones filled in)."""
        pos = self.free_positions
        if len(free) != len(pos):
            raise ValueError(f"expected {len(pos)} free indices, got {len(free)}")
        out = list(self.max_quality_indices())
        for i, v in zip(pos, free, strict=True):
            out[i] = int(v)
        self.validate(out)
        return tuple(out)

    def restrict(self, full: Sequence[int]) -> Indices:
        """Free parameters' indices of a full index vector."""
        self.validate(full)
        return tuple(int(full[i]) for i in self.free_positions)

    def validate(self, indices: Sequence[int]) -> None:
        if len(indices) != len(self.parameters):
            raise ValueError(f"expected {len(self.parameters)} indices, got {len(indices)}")
        for p, i in zip(self.parameters, indices, strict=True):
            if not 0 <= int(i) < len(p.values) or int(i) != i:
                raise ValueError(f"index {i!r} out of range for parameter {p.name!r}")

    # -- packing ------------------------------------------------------------------------------------

    def pack(self, indices: Sequence[int]) -> int:
        self.validate(indices)
        return pack_indices(indices)

    def unpack(self, packed: int) -> Indices:
        idx = unpack_indices(packed, len(self.parameters))
        self.validate(idx)
        return idx

    # -- meaning ------------------------------------------------------------------------------------

    def index_of(self, name: str, value: Any) -> int:
        """Index of ``value`` among parameter ``name``'s values (the names and values a store query
        returns and clients send back); ``True`` and ``1`` are different values, as JSON clients send
        both. ValueError names an unknown parameter or value."""
        if name not in self.names:
            raise ValueError(f"unknown parameter {name!r}; known: {list(self.names)}")
        p = self.parameters[self.names.index(name)]
        for i, v in enumerate(p.values):
            if (isinstance(v, bool) or isinstance(value, bool)) and not (
                    isinstance(v, bool) and isinstance(value, bool)):
                continue
            if v == value:
                return i
        raise ValueError(f"{value!r} is not a value of {name!r}; values: {list(p.values)}")

    def indices_of(self, values: Mapping[str, Any] | None) -> Indices:
        """Indices of ``{parameter: value}`` (a store query's settings); parameters left out stay at
        maximum quality. ValueError names an unknown parameter or value."""
        indices = list(self.max_quality_indices())
        for name, value in (values or {}).items():
            index = self.index_of(name, value)  # checks the name first
            indices[self.names.index(name)] = index
        return tuple(indices)

    def values_of(self, indices: Sequence[int]) -> dict[str, Any]:
        self.validate(indices)
        return {p.name: p.values[i] for p, i in zip(self.parameters, indices, strict=True)}

    def fields_of(self, indices: Sequence[int]) -> dict[str, Any]:
        """RenderSettings keyword values of a settings vector (later parameters win on overlap)."""
        self.validate(indices)
        out: dict[str, Any] = {}
        for p, i in zip(self.parameters, indices, strict=True):
            out.update(p.fields[i])
        return out

    def to_settings(self, indices: Sequence[int]) -> Any:
        """``sim_core.RenderSettings`` for a settings vector: max quality with this vector's fields."""
        base = sim_core.RenderSettings.max_quality()
        names = {f.name for f in dataclasses.fields(base)}
        flds = self.fields_of(indices)
        unknown = sorted(set(flds) - names)
        if unknown:
            raise ValueError(f"parameter fields {unknown} are not RenderSettings fields")
        return dataclasses.replace(base, **flds)

    def as_render_space(self, free_only: bool = False) -> dict[str, list[Any]]:
        """RenderSettings field -> candidate values (what ``sim_core.inert_parameters`` takes)."""
        out: dict[str, list[Any]] = {}
        for p in self.parameters:
            if free_only and p.name in self.fixed:
                continue
            for f in p.fields:
                for k, v in f.items():
                    vals = out.setdefault(k, [])
                    if v not in vals:
                        vals.append(v)
        return out

    # -- variants -----------------------------------------------------------------------------------

    def subset(self, names: Iterable[str]) -> ParameterSpace:
        """Only the named parameters are searched; the others are fixed at maximum quality."""
        keep = set(names)
        unknown = keep - set(self.names)
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}")
        fixed = dict(self.fixed)
        reasons = dict(self.fixed_reasons)
        for p in self.parameters:
            if p.name not in keep and p.name not in fixed:
                fixed[p.name] = p.max_quality
                reasons[p.name] = "not searched"
        return ParameterSpace(self.parameters, fixed, reasons)

    def with_values(self, wanted: Mapping[str, Sequence[Any]]) -> ParameterSpace:
        """Each named parameter cut down to the given values (kept in this space's order, the best kept
        value as its maximum quality); the others as they are. ValueError names an unknown parameter or
        value."""
        unknown = sorted(set(wanted) - set(self.names))
        if unknown:
            raise ValueError(f"unknown parameters {unknown}; known: {list(self.names)}")
        if self.fixed:
            raise ValueError("cut the values before fixing parameters")
        params = []
        for p in self.parameters:
            if p.name not in wanted:
                params.append(p)
                continue
            if not wanted[p.name]:
                raise ValueError(f"parameter {p.name!r} needs at least one value")
            idx = sorted({self.index_of(p.name, v) for v in wanted[p.name]})
            best = min(range(len(idx)), key=lambda k: abs(idx[k] - p.max_quality))
            params.append(Parameter(p.name, tuple(p.values[i] for i in idx), best,
                                    tuple(p.fields[i] for i in idx)))
        return ParameterSpace(tuple(params))

    def fix_inert(self, inert: Mapping[str, str]) -> ParameterSpace:
        """Fix parameters all of whose RenderSettings fields are inert (``{field: reason}``)."""
        fixed = dict(self.fixed)
        reasons = dict(self.fixed_reasons)
        for p in self.parameters:
            if p.name in fixed:
                continue
            if p.name in inert or all(f in inert for f in p.field_names):
                fixed[p.name] = p.max_quality
                reasons[p.name] = str(inert.get(p.name) or "; ".join(str(inert[f]) for f in p.field_names))
        return ParameterSpace(self.parameters, fixed, reasons)

    def to_stored(self) -> tuple[StoredParameter, ...]:
        """What a Pareto store carries to name settings (fixed parameters keep their single value)."""
        return tuple(StoredParameter(p.name, tuple(p.values), p.max_quality) for p in self.parameters)

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": [{"name": p.name, "values": list(p.values), "max_quality": p.max_quality,
                                "fields": [dict(f) for f in p.fields]} for p in self.parameters],
                "fixed": dict(self.fixed), "fixed_reasons": dict(self.fixed_reasons)}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> ParameterSpace:
        try:
            params = tuple(Parameter(str(p["name"]), tuple(p["values"]), int(p["max_quality"]),
                                     tuple(p.get("fields") or ())) for p in d["parameters"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed parameter space: {exc}") from exc
        return ParameterSpace(params, dict(d.get("fixed") or {}), dict(d.get("fixed_reasons") or {}))


# Sampling modes of the tracer, cheapest first (DESIGN.md, "Settings"): each sets RenderSettings.mode and
# its block (reference spacing or sub-pixel grid; irrelevant for 1 spp, kept at the default there).
_SAMPLING = (
    ("undersample_4x4", {"mode": "undersample", "block": 4}),
    ("undersample_2x2", {"mode": "undersample", "block": 2}),
    ("1spp", {"mode": "1spp", "block": 2}),
    ("adaptive_supersample_2x2", {"mode": "supersample", "block": 2}),
    ("fsaa_2x2", {"mode": "fsaa", "block": 2}),
)


#: DESIGN.md's table of values (cheapest first), what a job searches unless its ``space`` says otherwise.
DEFAULT_VALUES: dict[str, tuple[Any, ...]] = {
    "sampling": tuple(n for n, _ in _SAMPLING),
    "normal_threshold_deg": (45.0, 20.0, 5.0),
    "max_depth": (0, 1, 2, 3),
    "shadow_samples": (0, 1, 4, 16),
    "resolution_scale": (0.7, 0.8, 0.9, 1.0),
    "env_filter": ("off", "box", "bartlett"),
    "ao_samples": (0, 4, 8, 16),
    "multirate": (True, False),
}


def renderable_space() -> ParameterSpace:
    """Every value a job may search and the renderer, the engine's manual settings, REST and verify
    accept: DESIGN.md's table (:data:`DEFAULT_VALUES`) and, for shadow rays and AO samples, the steps
    between its 1-4-16 and 8-16, where a heavy scene's noise floor at 640x360 lies (bench/RESULTS.md,
    "Finer shadow and AO steps at the missed 640x360 frames"). Values are ordered cheapest first, so
    the maximum quality is the last value; parameter names are the RenderSettings field they set
    (``sampling`` sets ``mode`` and ``block``). The similarity threshold is the normal angle in degrees:
    loose 45, medium 20, strict 5."""
    params = (
        Parameter("sampling", tuple(n for n, _ in _SAMPLING), len(_SAMPLING) - 1,
                  tuple(f for _, f in _SAMPLING)),
        Parameter("normal_threshold_deg", (45.0, 20.0, 5.0), 2),
        Parameter("max_depth", (0, 1, 2, 3), 3),
        Parameter("shadow_samples", (0, 1, 2, 4, 8, 16), 5),
        Parameter("resolution_scale", (0.7, 0.8, 0.9, 1.0), 3),
        Parameter("env_filter", ("off", "box", "bartlett"), 2),
        Parameter("ao_samples", (0, 4, 8, 10, 12, 16), 5),
        Parameter("multirate", (True, False), 1),
    )
    return ParameterSpace(params)


def default_space() -> ParameterSpace:
    """The search space of a job that names no values: :func:`renderable_space` cut to DESIGN.md's
    table (8 parameters, 23,040 settings)."""
    return search_space()


def search_space(values: Mapping[str, Sequence[Any]] | None = None) -> ParameterSpace:
    """A job's search space: DESIGN.md's values (:data:`DEFAULT_VALUES`), each parameter named in
    ``values`` given those instead (any of :func:`renderable_space`'s, kept in its order). ValueError
    names an unknown parameter or value."""
    return renderable_space().with_values({**DEFAULT_VALUES, **(values or {})})


def space_holding(values: Mapping[str, Any] | None) -> ParameterSpace:
    """:func:`default_space` when it holds every ``{parameter: value}``, else :func:`renderable_space`.
    Evaluation cache keys name the space (what packed settings mean), so settings of DESIGN.md's table
    share their evaluations with the jobs that searched it."""
    space = default_space()
    try:
        space.indices_of(values)
    except ValueError:
        return renderable_space()
    return space


def stored_space(parameters: Iterable[StoredParameter]) -> ParameterSpace:
    """The space a store's settings were searched in (its parameters' values, as its job cut them from
    :func:`renderable_space`), for rendering its picks under the same cache keys."""
    return renderable_space().with_values({p.name: p.values for p in parameters})


def parse_space_argument(text: str) -> tuple[str, tuple[Any, ...]]:
    """``NAME=V1,V2,...`` (a command line's ``--space``) as a parameter and its values, each matched to
    one of :func:`renderable_space`'s by its text (``16``, ``0.9``, ``fsaa_2x2``, ``True``). ValueError
    names an unknown parameter or value."""
    name, sep, rest = text.partition("=")
    name = name.strip()
    space = renderable_space()
    if not sep or not rest.strip():
        raise ValueError(f"--space takes NAME=V1,V2,..., got {text!r}")
    if name not in space.names:
        raise ValueError(f"unknown parameter {name!r}; known: {list(space.names)}")
    known = space.parameters[space.names.index(name)].values
    values = []
    for item in (t.strip() for t in rest.split(",")):
        hits = [v for v in known if str(v) == item or (isinstance(v, float) and _float_text(item) == v)]
        if not hits:
            raise ValueError(f"{item!r} is not a value of {name!r}; values: {list(known)}")
        values.append(hits[0])
    return name, tuple(values)


def space_from_texts(texts: Mapping[str, str]) -> dict[str, tuple[Any, ...]]:
    """Values typed per parameter (``{"shadow_samples": "0, 1, 2, 4, 16"}``, as the add-on's parameter
    list shows them) as a job's ``space``: only the parameters whose values differ from
    :data:`DEFAULT_VALUES`, so a job whose list was left alone searches the default space under its
    cache keys (a blank text: the default values). ValueError names the parameter and the value."""
    space: dict[str, tuple[Any, ...]] = {}
    for name, text in texts.items():
        if not text.strip():
            continue
        _, values = parse_space_argument(f"{name}={text}")
        if set(values) != set(DEFAULT_VALUES.get(name, ())):
            space[name] = values
    return space


def values_text(values: Iterable[Any]) -> str:
    """Values as the add-on's parameter list shows them and :func:`space_from_texts` reads them."""
    return ", ".join(str(v) for v in values)


def _float_text(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def add_space_argument(parser: Any) -> None:
    """``--space NAME=V1,V2,...`` (repeatable) on an argparse parser: values per parameter instead of
    the default ones (a job's ``space``), collected as ``{name: values}`` in ``args.space``."""

    def parse(text: str) -> tuple[str, tuple[Any, ...]]:
        try:
            return parse_space_argument(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument("--space", type=parse, action="append", default=None, metavar="NAME=V1,V2,...",
                        help="search these values of a parameter instead of the default ones, e.g. "
                             "shadow_samples=0,1,2,4,16 (repeat per parameter; values: "
                             + "; ".join(f"{p.name} {','.join(map(str, p.values))}"
                                         for p in renderable_space().parameters) + ")")


def space_from_arguments(pairs: Sequence[tuple[str, tuple[Any, ...]]] | None) -> dict[str, tuple[Any, ...]]:
    """``args.space`` of :func:`add_space_argument` as ``{name: values}`` (a name given twice: the last)."""
    return dict(pairs or ())

