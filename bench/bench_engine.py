"""The Render Budget GPU engine's two paths outside Blender (the same code the engine runs in Blender):

* viewport (Rendered shading): a 960x540 region at the default viewport resolution 0.5, levels of 1/4,
  1/2 and 1 of that; time to each level after a restart, and what a draw call costs on the UI thread
  while the worker renders (the `show` + `latest` pair `view_draw` makes; it must never wait for a render);
  then a playback of N path frames fed as fast as a 24 fps timeline would, counting how many frames got
  an image of their own settings;
* final render: one path frame at 1920x1080 traced band by band, split into the tracer and the engine's
  own work (passes, Power pass, pricing).

Run: .venv/bin/python bench/bench_engine.py [--scene chess] [--scenes DIR] [--frames 24]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sim_core.loaders import load_gltf  # noqa: E402

import sim_core  # noqa: E402
from addon.core.engine_frame import CameraView, render_frame  # noqa: E402
from addon.core.engine_settings import FrameSettings, manual_indices  # noqa: E402
from addon.core.viewport import ViewportRenderer  # noqa: E402

DEFAULT_SCENES = REPO / "blend_scenes" / "build"
PRESETS = {
    "max quality": {},
    "1 spp, hard shadows": {"sampling": "1spp", "shadow_samples": "1", "ao_samples": "0", "max_depth": "1"},
    "undersample 4x4": {"sampling": "undersample_4x4", "normal_threshold_deg": "20.0", "ao_samples": "4",
                        "shadow_samples": "4"},
}


def ensure_scene(out: Path, name: str) -> Path:
    if not (out / name / "stats.json").exists():
        from blend_scenes.build import build

        build([name], out)
    return out / name


def projection(width: int, height: int, vfov: float) -> list[list[float]]:
    sy = 1 / np.tan(vfov / 2)
    return [[sy * height / width, 0, 0, 0], [0, sy, 0, 0], [0, 0, -1.0002, -0.2], [0, 0, -1, 0]]


def viewport_restart(data, frame, settings: FrameSettings, w: int, h: int) -> tuple[list[float], list[float]]:
    """Seconds from `show()` to each level's image, and the caller's CPU per draw while rendering."""
    times: list[float] = []
    done = threading.Event()
    t0 = [0.0]

    def on_frame(f) -> None:
        times.append(time.perf_counter() - t0[0])
        if f.final:
            done.set()

    vp = ViewportRenderer(on_frame=on_frame)
    vp.set_scene(data)
    vp.scenes.scene_for(data, vp.scene.key)  # the BVH exists already (built on the first view_update)
    draws = []
    try:
        proj = projection(w, h, frame["vfov"])
        t0[0] = time.perf_counter()
        vp.show(frame["matrix_world"], proj, w, h, settings, profile="mobile", fps=24)
        while not done.wait(0.016):  # a 60 Hz redraw loop: each draw repeats the same view
            c = time.thread_time()
            vp.show(frame["matrix_world"], proj, w, h, settings, profile="mobile", fps=24)
            vp.latest()
            draws.append(time.thread_time() - c)
    finally:
        vp.close()
    return times, draws


def playback(data, frames: list[dict], settings: list[FrameSettings], w: int, h: int, fps: float
             ) -> tuple[int, int]:
    """Frames shown at `fps` (one `show` per timeline frame); returns (frames that got their own image,
    frames fed)."""
    imaged: set[int] = set()
    vp = ViewportRenderer(on_frame=lambda f: imaged.add(f.key[1]))
    vp.set_scene(data)
    vp.scenes.scene_for(data, vp.scene.key)
    try:
        start = time.perf_counter()
        for k, (fr, fs) in enumerate(zip(frames, settings, strict=True)):
            while time.perf_counter() < start + k / fps:
                time.sleep(0.001)
            vp.show(fr["matrix_world"], projection(w, h, fr["vfov"]), w, h, fs, profile="mobile", fps=fps)
        vp.driver.wait_idle(120)
    finally:
        vp.close()
    matrices = {tuple(map(tuple, fr["matrix_world"])) for fr in frames}
    return len(imaged & matrices), len(frames)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="chess")
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    ap.add_argument("--frames", type=int, default=24, help="path frames played back")
    args = ap.parse_args()
    folder = ensure_scene(args.scenes, args.scene)
    data = load_gltf(folder / "scene.glb")
    path = json.loads((folder / "path.json").read_text())["frames"]
    frame = path[len(path) // 2]
    t = time.perf_counter()
    scene = sim_core.Scene.from_scene_data(data)
    print(f"{args.scene}: {data.triangles.shape[0]:,} triangles, BVH build {time.perf_counter() - t:.2f} s")

    region = (960, 540)
    w, h = round(region[0] * 0.5), round(region[1] * 0.5)
    print(f"\nViewport: region {region[0]}x{region[1]}, resolution 0.5 -> levels "
          f"{w // 4}x{h // 4}, {w // 2}x{h // 2}, {w}x{h}")
    print(f"{'settings':<22}{'level 1 s':>10}{'level 2 s':>10}{'level 3 s':>10}{'draws':>7}"
          f"{'draw CPU mean ms':>18}{'max ms':>8}")
    for name, preset in PRESETS.items():
        fs = FrameSettings("manual", manual_indices(preset))
        times, draws = viewport_restart(data, frame, fs, w, h)
        cpu = [1e3 * d for d in draws] or [0.0]
        print(f"{name:<22}" + "".join(f"{v:>10.3f}" for v in times) +
              f"{len(draws):>7}{statistics.mean(cpu):>18.3f}{max(cpu):>8.3f}")

    n = min(args.frames, len(path))
    picks = [path[int(i)] for i in np.linspace(0, len(path) - 1, n)]
    cheap = FrameSettings("manual", manual_indices(PRESETS["1 spp, hard shadows"]))
    shown, fed = playback(data, picks, [cheap] * n, w, h, 24.0)
    print(f"\nPlayback at 24 fps, {n} path frames, 1 spp: {shown} of {fed} frames got an image of their own "
          "(the others were skipped for a newer frame)")

    print("\nFinal render at 1920x1080, band by band:")
    print(f"{'settings':<22}{'total s':>9}{'tracer s':>10}{'engine s':>10}{'power W':>9}{'frame ms':>10}"
          f"{'fps reached':>12}")
    view = CameraView(frame["matrix_world"], frame["vfov"], 1920, 1080)
    for name in ("1 spp, hard shadows", "undersample 4x4"):  # max quality: minutes at this size
        fs = FrameSettings("manual", manual_indices(PRESETS[name]))
        t = time.perf_counter()
        out = render_frame(scene, view, fs, profile="mobile", fps=24.0)
        total = time.perf_counter() - t
        print(f"{name:<22}{total:>9.2f}{out.render_s:>10.2f}{total - out.render_s:>10.2f}{out.power_w:>9.3f}"
              f"{1e3 * out.frame_time_s:>10.2f}{out.achieved_fps:>12.3g}")


if __name__ == "__main__":
    main()
