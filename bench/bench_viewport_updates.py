"""Main-thread cost of the render engine's viewport on each edit (``view_update``): what it did before
(unless only the camera moved: a full translation, every mesh extracted again, and the scene's content
hash in ``ViewportRenderer.set_scene``) against now (``translate_update``: the incremental translation
through the viewport's translation cache; no hash), on the blend_scenes scenes in the real bpy module.

Each edit is made in Blender and the depsgraph evaluated; Blender's depsgraph_update_post handler (the
updates view_update would get) runs, on the same depsgraph, the incremental translation, then the
full one, then checks they give the same arrays. Times are the main thread's CPU time in ms (median of
``--repeat`` edits), so other jobs on the machine do not inflate them ("now wall ms": the same call's
wall-clock time, which also holds what Blender computes lazily on its own threads, and the machine's
load); the depsgraph's own evaluation is Blender's and not counted. ``BVH s`` is the native scene
build the viewport's worker thread does next (off the main thread; the native build releases the GIL).

Run: .venv/bin/python bench/bench_viewport_updates.py [--scene village --scene lab] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))

import bpy  # noqa: E402

import sim_core  # noqa: E402
from addon.core.engine_scene import fingerprint, needs_translation  # noqa: E402
from addon.translate import TranslationCache, depsgraph_updates, translate, translate_update  # noqa: E402

DEFAULT_SCENES = REPO / "blend_scenes" / "build"


def cpu_ms(fn: Callable[[], object], wall: list[float] | None = None) -> tuple[object, float]:
    """(fn(), this thread's CPU ms); ``wall``: append the wall-clock ms too."""
    t0, w0 = time.thread_time(), time.perf_counter()
    value = fn()
    if wall is not None:
        wall.append((time.perf_counter() - w0) * 1e3)
    return value, (time.thread_time() - t0) * 1e3


class Recorder:
    """The handler: per update, the incremental and the full translation's main-thread cost."""

    def __init__(self) -> None:
        self.cache = TranslationCache()
        self.rows: list[dict[str, float]] = []

    def on_update(self, _scene: object, depsgraph: bpy.types.Depsgraph) -> None:
        reads = self.cache.extractions
        wall: list[float] = []
        first = not self.cache.meshes
        inc, inc_ms = cpu_ms(lambda: translate_update(depsgraph, self.cache, force=first), wall)
        inc_reads = self.cache.extractions - reads
        full, full_ms = cpu_ms(lambda: translate(depsgraph, camera=False))
        _, hash_ms = cpu_ms(lambda: fingerprint(full.scene_data))
        # before: view_update translated everything and hashed it unless only a camera moved
        before = full_ms + hash_ms if needs_translation(depsgraph_updates(depsgraph)) else 0.0
        row = {"full": before, "full_reads": full.stats["mesh_reads"] if before else 0,
               "incremental": inc_ms, "inc_wall": wall[0], "inc_reads": inc_reads,
               "translated": inc is not None}
        if inc is not None:
            a, b = inc.scene_data, full.scene_data
            row["equal"] = all(np.array_equal(getattr(a, k), getattr(b, k))
                               for k in ("positions", "normals", "triangles", "material_ids", "object_ids"))
        self.rows.append(row)


def mesh_objects(scene: bpy.types.Scene) -> list[bpy.types.Object]:
    return [o for o in scene.objects if o.type == "MESH" and o.visible_get()]


def edits(scene: bpy.types.Scene) -> list[tuple[str, Callable[[int], None]]]:
    """(name, edit(i)): the edits an artist makes in Rendered shading."""
    objs = mesh_objects(scene)
    own = [o for o in objs if o.data.users == 1 and not o.modifiers]
    # the largest mesh with one user: its geometry edit is the dearest one to read again
    big = max(own or objs, key=lambda o: len(o.data.polygons))
    mover = objs[len(objs) // 2]
    mat = next((m for m in bpy.data.materials if m.users and m.node_tree
                and "Principled BSDF" in m.node_tree.nodes), None)
    cam = scene.camera

    def move(i: int) -> None:
        mover.location.x += 0.05 * (1 if i % 2 else -1)

    def camera(i: int) -> None:
        cam.location.z += 0.05 * (1 if i % 2 else -1)

    def recolour(i: int) -> None:
        if mat is not None:
            mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.3 + 0.01 * i

    def reshape(i: int) -> None:
        big.data.vertices[i % len(big.data.vertices)].co.z += 0.01
        big.data.update()

    def hide(i: int) -> None:
        mover.hide_viewport = not mover.hide_viewport

    return [("move object", move), ("move camera", camera), ("material", recolour),
            (f"geometry ({len(big.data.polygons):,} faces)", reshape), ("hide/show object", hide)]


def bench_scene(path: Path, repeat: int) -> list[tuple[str, ...]]:
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    for area_obj in scene.objects:  # the viewport shows what the view layer shows
        area_obj.select_set(False)
    rec = Recorder()
    bpy.app.handlers.depsgraph_update_post.append(rec.on_update)
    rows: list[tuple[str, ...]] = []
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        scene.frame_set(scene.frame_current)  # the first translation: everything read
        depsgraph.update()
        rec.rows.clear()
        first, full_first_ms = cpu_ms(lambda: translate(depsgraph, camera=False))
        t0 = time.thread_time()
        sim_core.Scene.from_scene_data(first.scene_data)
        bvh = time.thread_time() - t0
        rows.append(("first translation", f"{full_first_ms:,.0f}", "", "", f"{first.stats['mesh_reads']}",
                     "", "", f"{bvh:.2f}", ""))
        for name, edit in edits(scene):
            rec.rows.clear()
            for i in range(repeat):
                edit(i)
                depsgraph.update()
            mine = [r for r in rec.rows if r]
            if not mine:
                rows.append((name, "no update", "", "", "", "", "", "", ""))
                continue
            full = statistics.median(r["full"] for r in mine)
            inc = statistics.median(r["incremental"] for r in mine)
            inc_wall = statistics.median(r["inc_wall"] for r in mine)
            equal = all(r.get("equal", True) for r in mine)
            translated = sum(r["translated"] for r in mine)
            rows.append((name, f"{full:,.1f}", f"{inc:,.1f}", f"{inc_wall:,.1f}", f"{mine[-1]['full_reads']}",
                         f"{mine[-1]['inc_reads']}", f"{full / inc:,.1f}x" if full and inc > 0.05 else "-",
                         f"{bvh:.2f}" if translated else "-", "yes" if equal else "NO"))
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(rec.on_update)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", action="append", help="blend_scenes scene (repeatable; default village, lab)")
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    names = args.scene or ["village", "lab"]
    head = ("edit", "before ms", "now ms", "now wall ms", "reads before", "reads now", "speed-up", "BVH s",
            "equal")
    for name in names:
        path = args.scenes / name / "scene.blend"
        if not path.exists():
            from blend_scenes.build import build

            build([name], args.scenes)
        rows = bench_scene(path, args.repeat)
        print(f"\n{name}: main-thread CPU per viewport update (median of {args.repeat})")
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
        for k, r in enumerate((head, *rows)):
            cells = zip(r, widths, strict=True)
            print("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(cells)))
            if k == 0:
                print("-" * (sum(widths) + 2 * len(widths)))


if __name__ == "__main__":
    main()
