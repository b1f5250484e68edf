"""Hardware energy and timing model: prices a render's activity counters with a hardware profile.

Like the seeds' simulators (the adaptive-sampling seed, sec. 4): each hardware block's activity counter
times its energy per event, plus static power; cycles per block from each block's throughput; frame time
from the slowest unit and DRAM bandwidth. Power is what the modelled GPU draws at the frame rate it
actually reaches (:func:`sustained_power`): asked for ``fps`` frames per second, a frame that meets its
deadline (frame time <= 1 / fps) runs at ``fps`` and the GPU idles (leaking static power) for the rest of
the period, P = P_static + E_frame * fps, the way the power-budget paper measured power at a fixed frame
rate; a frame that misses it runs back to back at its own rate 1 / frame time (no vsync wait: the next
frame starts at once), P = P_static + E_frame / frame_time, the full-speed power. Power therefore never
exceeds the full-speed power. Profiles are TOML data files (``profiles/*.toml``); every constant there
carries its source or stated assumption.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import _core
from .comparator import COMPARATOR_TABLE, ComparatorStats, chain_energies, comparator_stats

__all__ = [
    "COMPARATOR_TABLE",
    "ComparatorStats",
    "EnergyReport",
    "Profile",
    "comparator_stats",
    "list_profiles",
    "load_profile",
    "price",
    "price_tiles",
    "sustained_power",
]

_PROFILE_DIR = Path(__file__).with_name("profiles")

# Counters the model prices (ARCHITECTURE.md); a missing counter counts as 0.
COUNTERS: tuple[str, ...] = (
    "rays_primary", "rays_shadow", "rays_reflection", "rays_refraction", "rays_ao", "rays_glossy",
    "rays_total", "bvh_node_visits", "triangle_tests", "shading_evals", "raygen_evals",
    "similarity_checks", "interpolations", "reprojections", "tile_buffer_reads", "tile_buffer_writes",
    "framebuffer_bytes", "gbuffer_prefetch_bytes", "cache_accesses", "cache_misses", "dram_bytes_read",
    "closest_hit_comparisons", "env_lookups", "env_filtered_lookups", "samples_traced",
    "samples_interpolated", "samples_reused", "pixels", "rays_alpha", "alpha_tests", "area_light_evals",
    "texture_fetches", "texel_reads", "texture_cache_misses", "texture_dram_bytes", "env_sh_evals",
    "resolve_taps", "resolve_bytes", "ambient_filter_taps",
)

# Which hardware unit each block runs on (units run concurrently; blocks on one unit add up, except the
# T&I unit whose traversal and intersection pipelines overlap).
BLOCK_UNIT: dict[str, str] = {
    "raygen": "srp", "shading": "srp", "similarity": "srp", "interpolation": "srp",
    "reprojection": "srp", "env_filter": "srp", "area_lights": "srp", "alpha_test": "srp", "texture": "srp",
    "resolve": "srp",
    "traversal": "ti", "intersection": "ti", "comparator": "ti", "cache": "ti",
    "tile_buffer": "tile_buffer",
    "dram": "dram", "framebuffer_dma": "dram", "gbuffer_prefetch": "dram", "texture_dram": "dram",
    "resolve_dram": "dram",
}
BLOCKS: tuple[str, ...] = tuple(BLOCK_UNIT)

_SECTIONS: dict[str, tuple[str, ...]] = {
    "clock": ("srp_hz", "ti_hz"),
    "throughput": ("srp_ops_per_cycle", "ti_box_tests_per_cycle", "ti_triangle_tests_per_cycle",
                   "cache_line_accesses_per_cycle", "tile_buffer_accesses_per_cycle", "dram_bytes_per_s",
                   "texels_per_cycle"),
    "ops": ("raygen", "shading", "similarity", "interpolation", "reprojection", "env_lookup",
            "env_filtered_lookup", "env_sh_eval", "texture_filter", "alpha_test", "area_light", "resolve_tap",
            "ambient_filter_tap"),
    "energy_pj": ("srp_op", "traversal_step", "triangle_test", "tile_buffer_access", "cache_line_access",
                  "env_texel_read", "texel_read", "dram_read_byte", "dram_write_byte", "dma_byte"),
    "comparator": ("energy_scale",),
    "cache": ("size_bytes", "line_bytes", "ways"),
    "texture_cache": ("size_bytes", "line_bytes", "ways"),
    "static": ("power_w",),
}


@dataclass(frozen=True)
class Profile:
    """A hardware profile: clocks, throughputs, per-event energies, cache geometries, static power."""

    name: str
    description: str
    clock: Mapping[str, float]
    throughput: Mapping[str, float]
    ops: Mapping[str, float]
    energy_pj: Mapping[str, float]
    comparator_style: str
    comparator_energy_scale: float
    cache_size_bytes: int
    cache_line_bytes: int
    cache_ways: int
    static_power_w: float
    source: str = ""
    texture_cache_size_bytes: int = 16384
    texture_cache_line_bytes: int = 64
    texture_cache_ways: int = 4

    @property
    def cache(self) -> Any:
        """The node/triangle cache geometry as the native ``CacheConfig`` (pass to ``render(cache=...)``)."""
        return _core.CacheConfig(self.cache_size_bytes, self.cache_line_bytes, self.cache_ways)

    @property
    def texture_cache(self) -> Any:
        """The texture cache geometry as a native ``CacheConfig`` (``render(texture_cache=...)``)."""
        return _core.CacheConfig(
            self.texture_cache_size_bytes, self.texture_cache_line_bytes, self.texture_cache_ways
        )

    @property
    def fingerprint(self) -> str:
        """A digest of every figure the model prices with (not the name, description or file): a cache
        keyed by it never serves figures of an edited or upgraded profile under the same name."""
        figures = {k: v for k, v in dataclasses.asdict(self).items()
                   if k not in ("name", "description", "source")}
        return hashlib.sha256(json.dumps(figures, sort_keys=True).encode()).hexdigest()[:16]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "") -> Profile:
        """Validate a parsed profile: every section and key present, numbers finite and in range."""
        where = source or "profile"
        for sec, keys in _SECTIONS.items():
            if sec not in data or not isinstance(data[sec], Mapping):
                raise ValueError(f"{where}: missing section [{sec}]")
            for k in keys:
                if k not in data[sec]:
                    raise ValueError(f"{where}: missing [{sec}] {k}")
                v = data[sec][k]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ValueError(f"{where}: [{sec}] {k} must be a finite number, got {v!r}")
                positive = sec in ("clock", "throughput", "cache", "texture_cache") or (sec == "comparator")
                if v < 0 or (positive and v <= 0):
                    raise ValueError(f"{where}: [{sec}] {k} must be {'> 0' if positive else '>= 0'}, got {v}")
        style = data["comparator"].get("style", "sync")
        if style not in ("sync", "async"):
            raise ValueError(f"{where}: [comparator] style must be 'sync' or 'async', got {style!r}")
        cache, texture_cache = data["cache"], data["texture_cache"]
        for sec, geometry in (("cache", cache), ("texture_cache", texture_cache)):
            for k in ("size_bytes", "line_bytes", "ways"):
                v = geometry[k]
                if int(v) != v or int(v) & (int(v) - 1):
                    raise ValueError(f"{where}: [{sec}] {k} must be a power-of-two integer, got {v}")
            if geometry["size_bytes"] < geometry["line_bytes"] * geometry["ways"]:
                raise ValueError(
                    f"{where}: [{sec}] size_bytes must hold at least one set (line_bytes * ways)"
                )
        name = data.get("name")
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}: 'name' must be a non-empty string")
        return cls(
            name=name,
            description=str(data.get("description", "")),
            clock=dict(data["clock"]),
            throughput=dict(data["throughput"]),
            ops=dict(data["ops"]),
            energy_pj=dict(data["energy_pj"]),
            comparator_style=style,
            comparator_energy_scale=float(data["comparator"]["energy_scale"]),
            cache_size_bytes=int(cache["size_bytes"]),
            cache_line_bytes=int(cache["line_bytes"]),
            cache_ways=int(cache["ways"]),
            static_power_w=float(data["static"]["power_w"]),
            source=source,
            texture_cache_size_bytes=int(texture_cache["size_bytes"]),
            texture_cache_line_bytes=int(texture_cache["line_bytes"]),
            texture_cache_ways=int(texture_cache["ways"]),
        )


def list_profiles() -> list[str]:
    """Names of the profiles shipped with the package (the TOML files in ``profiles/``)."""
    return sorted(p.stem for p in _PROFILE_DIR.glob("*.toml"))


def _profile_path(name_or_path: str | Path, relative_to: Path | None = None) -> Path:
    """A shipped profile's file by name, or a TOML file by path (relative to ``relative_to`` if given)."""
    p = Path(name_or_path)
    if relative_to is not None and not p.is_absolute() and p.suffix == ".toml":
        p = relative_to / p
    if p.suffix != ".toml" and not p.exists():
        p = _PROFILE_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise FileNotFoundError(
                f"no hardware profile named {name_or_path!r}; shipped profiles: {', '.join(list_profiles())}"
            )
    if not p.is_file():
        raise FileNotFoundError(f"hardware profile file not found: {p}")
    return p


def _read_profile(p: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """A profile file's data with its ``base`` profile's values under its own, section by section: a
    profile that differs from another in a few figures states only those (one source for the rest)."""
    with p.open("rb") as f:
        try:
            data = tomllib.load(f)
        except tomllib.TOMLDecodeError as e:
            raise ValueError(f"{p}: not valid TOML: {e}") from e
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str) or not base:
        raise ValueError(f"{p}: 'base' must name a shipped profile or a profile file, got {base!r}")
    if "name" not in data:
        raise ValueError(f"{p}: a profile with a 'base' must have its own 'name'")
    base_path = _profile_path(base, relative_to=p.parent)
    chain = (*seen, p.resolve())
    if base_path.resolve() in chain:
        raise ValueError(f"{p}: its base profiles form a cycle ({' -> '.join(str(c) for c in chain)} -> "
                         f"{base_path})")
    merged = _read_profile(base_path, chain)
    for key, value in data.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged


def load_profile(name_or_path: str | Path) -> Profile:
    """Load a shipped profile by name (``"mobile"``, ``"desktop"``) or any profile TOML file by path. A
    profile file may name a ``base`` profile (shipped name, or a path relative to the file) whose values
    it keeps where it does not set its own."""
    if isinstance(name_or_path, Profile):
        return name_or_path
    p = _profile_path(name_or_path)
    return Profile.from_dict(_read_profile(p), source=str(p))


def sustained_power(static_power_w: float, dynamic_energy_j: float, frame_time_s: float, fps: float
                    ) -> tuple[float, float]:
    """(power W, frame rate reached) of frames of ``dynamic_energy_j`` taking ``frame_time_s`` each when
    ``fps`` frames per second are asked for: the rate reached is ``fps`` when the frame meets its
    deadline (frame_time <= 1 / fps), else 1 / frame_time, and the power P_static + E_dynamic * that
    rate, so it never exceeds the full-speed power P_static + E_dynamic / frame_time (the one definition
    of power; ``price`` and the service's evaluator use it)."""
    for name, v in (("static power", static_power_w), ("dynamic energy", dynamic_energy_j),
                    ("frame time", frame_time_s)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a finite positive number, got {fps!r}")
    if frame_time_s <= 0:
        return static_power_w + dynamic_energy_j * fps, fps
    if frame_time_s <= 1.0 / fps:  # the deadline is met (the same test as ``deadline_met``)
        # min() keeps the result at or below the full-speed power even by a rounding step at the boundary
        return static_power_w + min(dynamic_energy_j * fps, dynamic_energy_j / frame_time_s), fps
    return static_power_w + dynamic_energy_j / frame_time_s, 1.0 / frame_time_s


@dataclass(frozen=True)
class EnergyReport:
    """Energy, timing and power of one frame on one hardware profile asked for a target frame rate."""

    profile: str
    fps: float  # the target frame rate asked for
    energy_j: dict[str, float]  # by block, plus "static" (P_static / achieved_fps); sums to total_energy_j
    cycles: dict[str, float]  # by block, in the cycles of the block's unit clock
    unit_time_s: dict[str, float]  # busy time of each unit: srp, ti, tile_buffer, dram
    bottleneck: str  # the unit that sets the frame time
    dynamic_energy_j: float
    total_energy_j: float
    frame_time_s: float
    deadline_met: bool  # frame_time_s <= 1 / fps
    power_w: float  # at the frame rate reached: P_static + E_dynamic * achieved_fps (<= power_full_speed_w)
    max_fps: float  # 1 / frame_time_s
    power_full_speed_w: float  # running flat out: P_static + E_dynamic / frame_time_s
    mrays_per_s: float  # rays_total / frame_time_s / 1e6
    perf_per_watt: float  # max_fps / power_full_speed_w (frames per joule at full speed)
    rays_total: int
    dram_bytes: int
    comparator: ComparatorStats
    blocks_used: tuple[str, ...] = field(default=())
    achieved_fps: float = 0.0  # the frame rate reached: fps if the deadline is met, else max_fps

    @property
    def unit_energy_j(self) -> dict[str, float]:
        """Dynamic energy by hardware unit (srp, ti, tile_buffer, dram); the T&I unit includes its cache."""
        out = {u: 0.0 for u in ("srp", "ti", "tile_buffer", "dram")}
        for b, u in BLOCK_UNIT.items():
            out[u] += self.energy_j[b]
        return out


def _counters_of(result: Any) -> tuple[dict[str, int], np.ndarray | None, Any]:
    if isinstance(result, Mapping):
        counters, hist, settings = result, None, None
    else:
        counters = getattr(result, "counters", None)
        if counters is None:
            raise ValueError("price() needs a RenderResult (with .counters) or a mapping of counters")
        hist = getattr(result, "comparator_histogram", None)
        settings = getattr(result, "settings", None)
    out: dict[str, int] = {}
    for k, v in counters.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            if isinstance(v, (float, np.floating)) and float(v).is_integer():
                v = int(v)
            else:
                raise ValueError(f"counter {k!r} must be an integer, got {v!r}")
        if v < 0:
            raise ValueError(f"counter {k!r} is negative ({v})")
        out[str(k)] = int(v)
    return out, hist, settings


def _filtered_reads_per_lookup(settings: Any) -> int:
    """SAT reads of one filtered environment lookup: 4 corners (box) or 9 (Bartlett), times 3 channels."""
    if str(getattr(settings, "env_filter", "")).lower() == "box":
        return 4 * 3
    return 9 * 3  # Bartlett, or settings unknown (a plain counter mapping): price the dearer lookup


def _reads_per_lookup(settings: Any) -> int:
    """Texel reads of one unfiltered environment lookup: the nearest texel with environment filtering off,
    else the four a bilinear lookup interpolates (settings unknown: the dearer)."""
    return 1 if str(getattr(settings, "env_filter", "")).lower() == "off" else 4


def _block_costs(prof: Profile, c: Mapping[str, Any], hist: np.ndarray | None, settings: Any, scene: Any
                 ) -> tuple[dict[str, Any], dict[str, Any], ComparatorStats | None]:
    """Energy (J) and cycles of every block for the counted events (the first half of :func:`price`),
    unit by unit: the shading processor, the traversal and intersection unit, the memories.

    Counts are integers (one frame) or equal-length integer arrays with ``hist`` one histogram row each
    (many tiles at once, :func:`price_tiles`): the same arithmetic, element by element; no comparator
    statistics then (None)."""

    def n(name: str) -> Any:
        return c.get(name, 0)

    energy: dict[str, Any] = {}
    cycles: dict[str, Any] = {}
    _srp_costs(prof, n, settings, scene, energy, cycles)
    comp = _ti_costs(prof, n, hist, energy, cycles)
    _memory_costs(prof, n, energy, cycles)

    for k, v in energy.items():
        if not np.all(np.isfinite(v)):
            raise ValueError(f"energy of block {k!r} is not finite")

    return energy, cycles, comp


#: Joules in a picojoule (the profile prices events in pJ).
_PJ = 1e-12


def _srp_costs(prof: Profile, n: Callable[[str], Any], settings: Any, scene: Any, energy: dict[str, Any],
               cycles: dict[str, Any]) -> None:
    """The shading processor's blocks: programmable work priced per op, texel reads, the resolve pass."""
    ops, e, thr = prof.ops, prof.energy_pj, prof.throughput
    pj = _PJ

    def srp_block(block: str, events: int, ops_per_event: float) -> None:
        energy[block] = events * ops_per_event * e["srp_op"] * pj
        cycles[block] = events * ops_per_event / thr["srp_ops_per_cycle"]

    srp_block("raygen", n("raygen_evals"), ops["raygen"])
    srp_block("shading", n("shading_evals"), ops["shading"])
    srp_block("similarity", n("similarity_checks"), ops["similarity"])
    srp_block("interpolation", n("interpolations"), ops["interpolation"])
    srp_block("reprojection", n("reprojections"), ops["reprojection"])
    env_map = scene is None or "environment_map" in (getattr(scene, "stats", {}) or {}).get("effects", ())
    lookups = n("env_lookups") if env_map else 0
    env_reads = (lookups * _reads_per_lookup(settings)
                 + n("env_filtered_lookups") * _filtered_reads_per_lookup(settings))
    env_ops = (lookups * ops["env_lookup"] + n("env_filtered_lookups") * ops["env_filtered_lookup"]
               + n("env_sh_evals") * ops["env_sh_eval"])
    energy["env_filter"] = (env_ops * e["srp_op"] + env_reads * e["env_texel_read"]) * pj
    cycles["env_filter"] = env_ops / thr["srp_ops_per_cycle"]
    # Shading features a scene may lack (their counters are then 0 and so is their cost): area lights,
    # alpha tests of cut-out materials, base-colour textures (filter ops + texel reads from the texture
    # cache; its line fills are DRAM traffic below).
    srp_block("area_lights", n("area_light_evals"), ops["area_light"])
    srp_block("alpha_test", n("alpha_tests"), ops["alpha_test"])
    srp_block("texture", n("texture_fetches"), ops["texture_filter"])
    energy["texture"] += n("texel_reads") * e["texel_read"] * pj
    # The filter arithmetic overlaps the texel reads; the slower of the two sets the block's time.
    texel_cycles = n("texel_reads") / thr["texels_per_cycle"]
    cycles["texture"] = (np.maximum(cycles["texture"], texel_cycles) if isinstance(texel_cycles, np.ndarray)
                         else max(cycles["texture"], texel_cycles))  # arrays: price_tiles
    # The resolve pass (sub-samples, or AO to denoise): the pixel filter's taps and the ambient filter's,
    # and the sample buffer written to DRAM by the tiles and read back once.
    energy["resolve"] = (n("resolve_taps") * ops["resolve_tap"]
                         + n("ambient_filter_taps") * ops["ambient_filter_tap"]) * e["srp_op"] * pj
    cycles["resolve"] = (n("resolve_taps") * ops["resolve_tap"]
                         + n("ambient_filter_taps") * ops["ambient_filter_tap"]) / thr["srp_ops_per_cycle"]


def _ti_costs(prof: Profile, n: Callable[[str], Any], hist: np.ndarray | None, energy: dict[str, Any],
              cycles: dict[str, Any]) -> ComparatorStats | None:
    """The traversal and intersection unit's blocks: tree steps, triangle tests, the closest-hit
    comparator (from its histogram) and the node cache."""
    e, thr = prof.energy_pj, prof.throughput
    pj = _PJ

    # One node visit is one step of the 4-wide tree: four ray-box tests (and the ordering of the hit
    # children), priced per step; the unit's box testers set the step rate.
    energy["traversal"] = n("bvh_node_visits") * e["traversal_step"] * pj
    cycles["traversal"] = n("bvh_node_visits") * int(_core.BVH_NODE_BOXES) / thr["ti_box_tests_per_cycle"]
    energy["intersection"] = n("triangle_tests") * e["triangle_test"] * pj
    cycles["intersection"] = n("triangle_tests") / thr["ti_triangle_tests_per_cycle"]
    comparisons = n("closest_hit_comparisons")
    if hist is not None and np.ndim(hist) == 2:  # many tiles: one histogram row each
        sync_e, async_e = chain_energies(prof.comparator_energy_scale)
        per_chain = async_e if prof.comparator_style == "async" else sync_e
        if np.any((hist.sum(axis=1) == 0) & (comparisons > 0)):
            raise ValueError("closest_hit_comparisons > 0 but a tile carries no comparator histogram")
        energy["comparator"] = hist.astype(np.float64) @ per_chain
        comp = None
    else:
        comp = comparator_stats(hist, prof.comparator_energy_scale)
        if comp.comparisons == 0 and comparisons > 0:
            raise ValueError("closest_hit_comparisons > 0 but the render carries no comparator histogram")
        energy["comparator"] = comp.async_energy_j if prof.comparator_style == "async" else comp.sync_energy_j
    cycles["comparator"] = 0.0  # inside the intersection pipeline; its latency is hidden there
    energy["cache"] = n("cache_accesses") * e["cache_line_access"] * pj
    cycles["cache"] = n("cache_accesses") / thr["cache_line_accesses_per_cycle"]
    return comp


def _memory_costs(prof: Profile, n: Callable[[str], Any], energy: dict[str, Any],
                  cycles: dict[str, Any]) -> None:
    """The tile buffer and DRAM traffic: bytes read and written, with the DMA that moves them."""
    e, thr, clk = prof.energy_pj, prof.throughput, prof.clock
    pj = _PJ

    tb = n("tile_buffer_reads") + n("tile_buffer_writes")
    energy["tile_buffer"] = tb * e["tile_buffer_access"] * pj
    cycles["tile_buffer"] = tb / thr["tile_buffer_accesses_per_cycle"]

    bytes_per_srp_cycle = thr["dram_bytes_per_s"] / clk["srp_hz"]
    energy["dram"] = n("dram_bytes_read") * e["dram_read_byte"] * pj
    cycles["dram"] = n("dram_bytes_read") / bytes_per_srp_cycle
    energy["framebuffer_dma"] = n("framebuffer_bytes") * (e["dram_write_byte"] + e["dma_byte"]) * pj
    cycles["framebuffer_dma"] = n("framebuffer_bytes") / bytes_per_srp_cycle
    energy["gbuffer_prefetch"] = n("gbuffer_prefetch_bytes") * (e["dram_read_byte"] + e["dma_byte"]) * pj
    cycles["gbuffer_prefetch"] = n("gbuffer_prefetch_bytes") / bytes_per_srp_cycle
    energy["texture_dram"] = n("texture_dram_bytes") * e["dram_read_byte"] * pj
    cycles["texture_dram"] = n("texture_dram_bytes") / bytes_per_srp_cycle
    energy["resolve_dram"] = n("resolve_bytes") * (e["dram_write_byte"] + e["dram_read_byte"]
                                                   + 2 * e["dma_byte"]) * pj
    cycles["resolve_dram"] = 2 * n("resolve_bytes") / bytes_per_srp_cycle


def price_tiles(counters: Mapping[str, Any], histograms: np.ndarray | None, profile: Profile | str | Path, *,
                settings: Any = None, scene: Any = None) -> np.ndarray:
    """Dynamic energy (J) of many tiles at once: what :func:`price` gives each tile's counters and
    comparator histogram (``dynamic_energy_j``), the same arithmetic on arrays (equal to rounding).

    ``counters``: counter name -> one non-negative integer count per tile (a render's ``tile_counters``
    columns); ``histograms``: (tiles, 25) comparator histograms or None; ``settings`` / ``scene`` as
    :func:`price` reads them from a render. Dynamic energy does not depend on the frame rate."""
    prof = load_profile(profile) if not isinstance(profile, Profile) else profile
    cols: dict[str, np.ndarray] = {}
    length = None
    for k, v in counters.items():
        arr = np.asarray(v)
        if arr.ndim != 1 or (length is not None and arr.shape[0] != length):
            raise ValueError(f"counter {k!r} must be one count per tile ({length} tiles), got {arr.shape}")
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"counter {k!r} must hold integers, got {arr.dtype}")
        if arr.size and np.issubdtype(arr.dtype, np.signedinteger) and (arr < 0).any():
            raise ValueError(f"counter {k!r} has a negative count")
        length = arr.shape[0]
        cols[str(k)] = arr.astype(np.int64)
    if length is None:
        raise ValueError("price_tiles needs at least one counter")
    for k in COUNTERS:  # a missing counter counts 0 (as in price), as a column: every block is an array
        cols.setdefault(k, np.zeros(length, dtype=np.int64))
    bins = int(_core.COMPARATOR_BITS) + 1
    hist = np.zeros((length, bins), np.int64) if histograms is None else np.asarray(histograms)
    if hist.shape != (length, bins) or not np.issubdtype(hist.dtype, np.integer) or (hist < 0).any():
        raise ValueError(f"comparator histograms must be ({length}, {bins}) non-negative integers, got "
                         f"{hist.shape}")
    hist = hist.astype(np.int64)
    energy, _cycles, _comp = _block_costs(prof, cols, hist, settings, scene)
    total = np.zeros(length, dtype=np.float64)
    for b in BLOCKS:  # in price()'s order
        total += energy[b]
    return total


def price(result: Any, profile: Profile | str | Path, fps: float, *, scene: Any = None) -> EnergyReport:
    """Price one rendered frame asked for at ``fps``: energy and cycles by block, frame time, deadline,
    the frame rate reached and the power drawn at it (:func:`sustained_power`), perf/W.

    ``result`` is a ``RenderResult`` (its ``counters``, ``comparator_histogram`` and, when present,
    ``settings``) or a plain mapping of counter names to counts. A block whose counters are 0 costs
    exactly 0 J and 0 cycles. ``scene`` (optional): when given and its environment is a constant colour,
    environment lookups of missed rays cost nothing (a constant is a register, not a map lookup).
    """
    prof = load_profile(profile) if not isinstance(profile, Profile) else profile
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a finite positive number, got {fps!r}")
    fps = float(fps)
    c, hist, settings = _counters_of(result)

    def n(name: str) -> int:
        return c.get(name, 0)

    energy, cycles, comp = _block_costs(prof, c, hist, settings, scene)
    clk, thr = prof.clock, prof.throughput
    unit_time = {
        "srp": sum(cycles[b] for b in BLOCKS if BLOCK_UNIT[b] == "srp") / clk["srp_hz"],
        # Traversal and intersection pipelines (and the cache ports feeding them) work concurrently.
        "ti": max(cycles["traversal"], cycles["intersection"], cycles["cache"]) / clk["ti_hz"],
        "tile_buffer": cycles["tile_buffer"] / clk["srp_hz"],
        "dram": (n("dram_bytes_read") + n("framebuffer_bytes") + n("gbuffer_prefetch_bytes")
                 + n("texture_dram_bytes") + 2 * n("resolve_bytes")) / thr["dram_bytes_per_s"],
    }
    bottleneck = max(unit_time, key=lambda u: unit_time[u])
    frame_time = unit_time[bottleneck]
    dynamic = math.fsum(energy[b] for b in BLOCKS)
    power, achieved = sustained_power(prof.static_power_w, dynamic, frame_time, fps)
    energy_all = {b: energy[b] for b in BLOCKS}
    energy_all["static"] = prof.static_power_w / achieved  # leakage over one frame period at that rate
    total = math.fsum(energy_all.values())
    rays = n("rays_total")
    if frame_time > 0:
        max_fps = 1.0 / frame_time
        power_full = prof.static_power_w + dynamic / frame_time
        mrays = rays / frame_time / 1e6
    else:
        max_fps, power_full, mrays = math.inf, prof.static_power_w, 0.0
    perf_per_watt = max_fps / power_full if power_full > 0 and math.isfinite(max_fps) else 0.0
    return EnergyReport(
        profile=prof.name,
        fps=fps,
        energy_j=energy_all,
        cycles=cycles,
        unit_time_s=unit_time,
        bottleneck=bottleneck,
        dynamic_energy_j=dynamic,
        total_energy_j=total,
        frame_time_s=frame_time,
        deadline_met=frame_time <= 1.0 / fps,
        power_w=power,
        max_fps=max_fps,
        power_full_speed_w=power_full,
        mrays_per_s=mrays,
        perf_per_watt=perf_per_watt,
        rays_total=rays,
        dram_bytes=n("dram_bytes_read") + n("framebuffer_bytes") + n("gbuffer_prefetch_bytes")
        + n("texture_dram_bytes") + 2 * n("resolve_bytes"),
        comparator=comp,
        blocks_used=tuple(b for b in BLOCKS if energy[b] > 0),
        achieved_fps=achieved,
    )
