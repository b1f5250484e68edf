"""The maximum-quality references of a build's pricing cameras, kept on disk between pricing rounds.

A pricing task renders its camera's reference (a whole frame, or the tile estimator's design: the
auxiliary frames and the reference's windows) before it prices any setting. The builder prices the same
cameras again in later rounds (the search's probes that kept up, bridging), each in whichever worker
process the executor picks, whose own few designs (``camera._DESIGNS``) have moved on by then: without
this store every such round rendered each camera's reference again, the costliest render of the round.

Files are numpy ``.npz`` archives (no pickle), written under a temporary name and renamed, so a reader
sees a whole file or none. A file that is missing or unreadable is rendered again: the figures are the
same either way, bit for bit. The directory belongs to one build and must exist: a worker that does not
see it (a Dask worker on another machine) reads and writes nothing and renders as before. The
directory holds at most ``max_bytes`` (:data:`MAX_BYTES`: a 1280x720 design takes about 9 MB, so 150
cameras about 1.4 GB); a reference that would pass it is not kept, and is rendered again when asked.
"""

from __future__ import annotations

import hashlib
import os
import uuid
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from service.display_pricing.sampling import CameraDesign
from service.params import Indices

#: Per-block auxiliary figures of one setting: error sums, counters, histograms (and, when just
#: rendered, its auxiliary frame, which the estimator does not read and the store does not keep).
Measure = tuple[Any, ...]

_INTS = ("W", "H", "B", "nbx", "nby", "pad", "interior")

#: The most a build's references take on disk: beyond it they are rendered again instead of read.
MAX_BYTES = 2 << 30


class ReferenceStore:
    """Whole-frame references and tile-estimator designs of a build's cameras, by a key naming all they
    depend on (scene, camera and its size, estimator, metric, the space's max quality)."""

    def __init__(self, directory: str | Path, max_bytes: int = MAX_BYTES) -> None:
        self.directory = Path(directory)
        self.max_bytes = int(max_bytes)

    def _used_bytes(self) -> int:
        """What the directory holds now (every worker's files, half-written ones included)."""
        total = 0
        with os.scandir(self.directory) as entries:
            for entry in entries:
                try:
                    total += entry.stat().st_size
                except OSError:  # renamed or removed meanwhile
                    continue
        return total

    def _path(self, kind: str, key: tuple[str, ...]) -> Path:
        digest = hashlib.sha256(repr((kind, *key)).encode()).hexdigest()[:32]
        return self.directory / f"{kind}-{digest}.npz"

    def _load(self, kind: str, key: tuple[str, ...]) -> dict[str, np.ndarray] | None:
        path = self._path(kind, key)
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {name: z[name] for name in z.files}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # missing or cut short
            return None
        return data if str(data.get("key", "")) == repr(key) else None  # (a digest collision)

    def _save(self, kind: str, key: tuple[str, ...], arrays: dict[str, np.ndarray]) -> None:
        if not self.directory.is_dir():  # not this machine's build: nothing is kept
            return
        path = self._path(kind, key)
        tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex}.npz")
        try:
            with open(tmp, "wb") as f:
                np.savez(f, key=np.asarray(repr(key)), **arrays)
            if self._used_bytes() > self.max_bytes:  # over the cap with this one: render it again
                tmp.unlink(missing_ok=True)
                return
            os.replace(tmp, path)
        except OSError:  # a full disk costs renders, not the pricing
            tmp.unlink(missing_ok=True)

    def load_frame(self, key: tuple[str, ...]) -> np.ndarray | None:
        """A whole-frame reference image saved under ``key``, or None."""
        data = self._load("frame", key)
        return None if data is None else data["image"]

    def save_frame(self, key: tuple[str, ...], image: np.ndarray) -> None:
        self._save("frame", key, {"image": np.asarray(image)})

    def load_design(self, key: tuple[str, ...]) -> tuple[CameraDesign, dict[Indices, Measure]] | None:
        """A camera's design, its reference windows traced, and its probes' measures; or None."""
        data = self._load("design", key)
        if data is None:
            return None
        try:
            return _design_from(data)
        except (KeyError, ValueError, IndexError):
            return None

    def save_design(self, key: tuple[str, ...], d: CameraDesign, measures: dict[Indices, Measure]) -> None:
        """Saves ``d`` once its reference windows are traced (``reference_tiles`` set)."""
        if d.reference_tiles is None:
            raise ValueError("a design is saved with its reference windows traced")
        self._save("design", key, _design_arrays(d, measures))


def _design_arrays(d: CameraDesign, measures: dict[Indices, Measure]) -> dict[str, np.ndarray]:
    blocks = sorted(d.regions)
    cnt, hist, owner, size = d.reference_tiles  # type: ignore[misc]
    out = {"ints": np.asarray([getattr(d, n) for n in _INTS], dtype=np.int64),
           "aux_size": np.asarray(d.aux_size, dtype=np.int64), "aux_reference": d.aux_reference,
           "pi": d.pi, "sampled": d.sampled, "counts": d.counts,
           "region_blocks": np.asarray(blocks, dtype=np.int64),
           "region_rects": np.asarray([d.regions[b] for b in blocks], dtype=np.int64).reshape(-1, 4),
           "reference_blocks": np.asarray(sorted(d.reference), dtype=np.int64),
           "tiles_counters": cnt, "tiles_histograms": hist, "tiles_blocks": owner,
           "tiles_size": np.asarray(size, dtype=np.int64),
           "measure_settings": np.asarray(list(measures), dtype=np.int64).reshape(len(measures), -1)}
    for b in sorted(d.reference):
        out[f"reference_{b}"] = d.reference[b]
    for i, m in enumerate(measures.values()):
        out[f"measure_{i}_error"], out[f"measure_{i}_counters"], out[f"measure_{i}_histograms"] = m[:3]
    return out


def _design_from(z: dict[str, np.ndarray]) -> tuple[CameraDesign, dict[Indices, Measure]]:
    ints = dict(zip(_INTS, (int(v) for v in z["ints"]), strict=True))
    regions = {int(b): tuple(int(v) for v in r) for b, r in zip(z["region_blocks"], z["region_rects"],
                                                                 strict=True)}
    d = CameraDesign(ints["W"], ints["H"], ints["B"], ints["nbx"], ints["nby"], ints["pad"],
                     (int(z["aux_size"][0]), int(z["aux_size"][1])), z["aux_reference"], z["pi"],
                     z["sampled"], regions, z["counts"], ints["interior"],  # type: ignore[arg-type]
                     {int(b): z[f"reference_{int(b)}"] for b in z["reference_blocks"]},
                     (z["tiles_counters"], z["tiles_histograms"], z["tiles_blocks"],
                      (int(z["tiles_size"][0]), int(z["tiles_size"][1]))))
    measures: dict[Indices, Measure] = {
        tuple(int(i) for i in idx): (z[f"measure_{k}_error"], z[f"measure_{k}_counters"],
                                     z[f"measure_{k}_histograms"], None)
        for k, idx in enumerate(z["measure_settings"])}
    return d, measures
