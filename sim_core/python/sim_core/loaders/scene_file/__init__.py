"""The render-budget scene file: a ``SceneData`` in one self-contained, safe, deterministic file.

What the add-on's depsgraph translator produces travels to jobs (local or on the service) in this format,
so a job optimises exactly the scene the render engine renders. Layout (version 1):

- a ZIP archive whose entries are all *stored* (uncompressed: no decompression bombs, and the bytes are a
  pure function of the content), written in a fixed order with fixed timestamps and attributes;
- ``manifest.json`` (first entry, UTF-8, sorted keys): ``format`` = ``"render-budget-scene"``, ``version``,
  ``arrays`` (name -> dtype and shape), ``materials`` and ``lights`` (the fields of
  ``sim_core.Material`` / ``sim_core.Light``), ``cameras``, ``environment`` (``{"kind": "default"}``,
  ``{"kind": "color", "color": [r, g, b]}`` or ``{"kind": "map", "array": "environment"}``, each with
  ``strength`` and ``rotation``), ``textures`` (``{array, colorspace, wrap_u, wrap_v, name}``),
  ``object_names`` and ``notes`` (what the translator approximated: ``{severity, subject, message}``);
- ``arrays/<name>.npy``: NumPy format 1.0, little-endian, C order, read with ``allow_pickle=False``:
  ``positions`` (V, 3) <f4, ``triangles`` (T, 3) <u4, optional ``normals`` (V, 3) <f4 and ``uvs`` (V, 2) <f4,
  ``material_ids`` and ``object_ids`` (T,) <u4, ``environment`` (H, W, 3) <f4 or <f2, ``texture_<i>``
  (H, W, C) |u1, <f4 or <f2 with C in 1..4 (row 0 at the top).

The scene id of a file is the SHA-256 of its bytes; the same scene always writes the same bytes. Reading
validates like any upload: entry names, sizes against the limits, dtypes and shapes against the manifest,
finite values, index ranges; errors are ``ValueError`` naming the problem (never a path or a Python
exception's internals). Negative or non-finite environment texels are clamped with a warning.

The package: :mod:`.format` (constants, limits, :class:`SceneFile`), :mod:`.writer`, :mod:`.reader` (the
container and its arrays) and :mod:`.records` (the manifest's records as scene data).
"""

from __future__ import annotations

from .format import DEFAULT_LIMITS, FORMAT, MANIFEST, MEDIA_TYPE, SUFFIX, VERSION, Limits, SceneFile
from .reader import is_scene_file, load_scene_file, read_scene_file
from .writer import scene_file_bytes, write_scene_file

__all__ = ["DEFAULT_LIMITS", "FORMAT", "MANIFEST", "MEDIA_TYPE", "SUFFIX", "VERSION", "Limits", "SceneFile",
           "is_scene_file", "load_scene_file", "read_scene_file", "scene_file_bytes", "write_scene_file"]
