"""Command line: query a real store; argument validation; serve flags."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from service import cli
from service.store import Frontier, ParetoStore, StoredParameter, pack_indices


def _store_file(tmp_path, frame_times=None, static_power_w=None):
    params = (StoredParameter("max_depth", (0, 1, 2, 3), 3),
              StoredParameter("shadow_samples", (0, 1, 4, 16), 3))
    fr = [Frontier.from_points([pack_indices([k, k]) for k in range(4)], [0.3, 0.1, 0.02, 0.0],
                               [1.0 + v, 1.5 + v, 2.0 + v, 3.0 + v]) for v in range(6)]
    if frame_times is not None:
        fr = [Frontier(f.packed, f.error, f.power_w, np.asarray(frame_times)) for f in fr]
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)])
    views = np.tile(np.arange(6), (8, 1))
    store = ParetoStore(params, np.zeros(3), 4.0, 0, np.array([-1]), corners, views, fr,
                        vfov=math.radians(40), aspect=1.5,
                        meta={} if static_power_w is None else {"static_power_w": static_power_w})
    f = tmp_path / "store.json"
    f.write_text(store.to_json())
    return f


def test_query_json(tmp_path, capsys) -> None:
    f = _store_file(tmp_path)
    rc = cli.main(["query", str(f), "--position", "1", "1", "1", "--direction", "0", "0", "-1", "--fov", "40",
                   "--power-budget", "7.6", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["view"] == 5 and out["settings"] == {"max_depth": 2, "shadow_samples": 4}
    assert out["power_w"] == pytest.approx(7.0, abs=1e-3) and not out["infeasible"] and not out["clamped"]


def test_query_reports_the_frame_rate(tmp_path, capsys) -> None:
    """The most accurate setting misses 30 fps: an error budget it alone keeps gets the most accurate one
    that keeps up (infeasible), with its frame rate; a store without frame times says it does not know."""
    f = _store_file(tmp_path, frame_times=[0.005, 0.01, 0.02, 0.1])
    args = ["query", str(f), "--position", "1", "1", "1", "--direction", "0", "0", "-1",
            "--error-budget", "0"]
    assert cli.main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["settings"] == {"max_depth": 2, "shadow_samples": 4} and out["infeasible"]
    assert out["meets_fps"] is True and out["fps"] == 30.0 and out["fps_target"] == 30.0
    assert out["frame_time_s"] == pytest.approx(0.02, rel=1e-4)
    # no per-camera figures in this store: the prediction for the camera is the stored figure
    assert (out["expected_error"], out["expected_power_w"]) == (out["error"], out["power_w"])
    assert cli.main(args) == 0
    text = capsys.readouterr().out
    assert "30.0 of 30 fps (20.0 ms a frame)" in text
    assert "figures: of a size the store does not record" in text  # this store does not say
    store = ParetoStore.from_json(f.read_text())
    store.meta.update(figures_resolution=[640, 360], display_pricing="tiles:ssim")
    f.write_text(store.to_json())
    assert cli.main(args) == 0
    assert "figures: for a 640x360 display" in capsys.readouterr().out
    assert cli.main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["figures_resolution"], out["figures_kind"]) == ([640, 360], "display")
    (tmp_path / "old").mkdir()
    f = _store_file(tmp_path / "old")
    assert cli.main(["query", str(f), *args[2:]]) == 0
    assert "unknown (the store predates frame times" in capsys.readouterr().out


def test_query_text_flags_and_matrix(tmp_path, capsys) -> None:
    f = _store_file(tmp_path)
    m = [str(v) for v in np.eye(4).ravel()]
    rc = cli.main(["query", str(f), "--position", "9", "9", "9", "--matrix", *m, "--error-budget", "-1"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "clamped" in text and "infeasible" in text and "predicted power" in text


@pytest.mark.parametrize("argv", [
    ["query", "missing.json", "--position", "0", "0", "0", "--direction", "1", "0", "0",
     "--power-budget", "1"],
])
def test_query_errors_exit_nonzero(argv, capsys) -> None:
    assert cli.main(argv) == 1
    assert "error" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["query", "s.json", "--position", "0", "0", "--direction", "1", "0", "0", "--power-budget", "1"],
    ["query", "s.json", "--position", "0", "0", "0", "--direction", "1", "0", "0"],
    ["query", "s.json", "--position", "0", "0", "0", "--direction", "1", "0", "0", "--power-budget", "1",
     "--error-budget", "1"],
    ["query", "s.json", "--position", "nan", "0", "0", "--direction", "1", "0", "0", "--power-budget", "1"],
    ["optimize", "scene.glb", "--out", "x.json"],
    ["optimize", "scene.glb", "--path", "p.json", "--out", "x.json", "--threshold-power", "-1"],
    ["optimize", "scene.glb", "--path", "p.json", "--out", "x.json", "--space", "shadow_samples=3"],
])
def test_bad_arguments(argv) -> None:
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2


def test_serve_flags() -> None:
    args = cli.build_parser().parse_args(["serve", "--host", "0.0.0.0", "--port", "9000", "--data-dir", "d",
                                          "--dask-scheduler", "tcp://h:8786", "--token", "t",
                                          "--allowed-hosts", "a.example,b.example"])
    assert cli.serve_overrides(args) == {
        "host": "0.0.0.0", "port": 9000, "data_dir": Path("d"), "dask_scheduler": "tcp://h:8786",
        "token": "t", "allowed_hosts": "a.example,b.example"}
    # Options not given are not settings at all: RENDER_BUDGET_* variables keep their say.
    assert cli.serve_overrides(cli.build_parser().parse_args(["serve"])) == {}


@pytest.mark.parametrize("text,size", [("4096", 4096), ("2G", 2 * 1024**3), ("500M", 500 * 1024**2),
                                       ("1.5GiB", int(1.5 * 1024**3)), ("64k", 65536), ("3 MB", 3 * 1024**2)])
def test_byte_sizes(text: str, size: int) -> None:
    assert cli.byte_size(text) == size


@pytest.mark.parametrize("text", ["", "G", "-1M", "lots", "nanG", "0"])
def test_bad_byte_sizes(text: str) -> None:
    import argparse

    with pytest.raises(argparse.ArgumentTypeError):
        cli.byte_size(text)


def test_cache_stats_and_prune(tmp_path, capsys) -> None:
    from service.eval_cache import CacheKey, EvalCache, Evaluation
    from service.storage import EVAL_CACHE_NAME, Storage

    storage = Storage(tmp_path)
    storage.add_scene(scene_id="ab" * 32, size=1, content_hash="busy", stats={}, inert={}, cameras=0)
    storage.create_job(scene_id="ab" * 32, spec={})  # queued: its scene's evaluations must stay
    storage.close()
    with EvalCache(tmp_path / EVAL_CACHE_NAME, max_bytes=None) as c:
        for scene in ("busy", "idle"):
            for k in range(20):
                key = CacheKey(scene, f"cam{k}", "ssim-v1", "mobile", 32, 24, 30.0)
                c.put_many(key, [(p, Evaluation(0.1, 1.0, 0.01, {"pad": "x" * 400})) for p in range(40)])
    assert cli.main(["cache", "stats", "--data-dir", str(tmp_path), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["entries"] == 1600 and stats["scenes"] == 2 and stats["cameras"] == 40
    assert cli.main(["cache", "prune", "--data-dir", str(tmp_path), "--max-bytes", "64k"]) == 0
    assert "1 scenes of running jobs kept" in capsys.readouterr().out
    with EvalCache(tmp_path / EVAL_CACHE_NAME) as c:
        assert c.stats()["scenes"] == 1 and len(c) == 800  # only the busy scene's evaluations are left
    assert cli.main(["cache", "stats", "--cache", str(tmp_path / "none.sqlite")]) == 1
    assert "no evaluation cache" in capsys.readouterr().err


def test_query_at_another_frame_rate(tmp_path, capsys) -> None:
    """--fps 60: the 20 ms setting misses 60 fps, so the error budget it alone kept is given up for the
    10 ms one (marked infeasible), its power repriced for 60 fps; a store without the static power
    refuses another rate with a clear message."""
    f = _store_file(tmp_path, frame_times=[0.005, 0.01, 0.02, 0.1], static_power_w=0.5)
    args = ["query", str(f), "--position", "1", "1", "1", "--direction", "0", "0", "-1", "--error-budget",
            "0.03", "--json"]
    assert cli.main(args) == 0
    at30 = json.loads(capsys.readouterr().out)
    assert at30["settings"] == {"max_depth": 2, "shadow_samples": 4} and not at30["infeasible"]
    assert cli.main([*args, "--fps", "60"]) == 0
    at60 = json.loads(capsys.readouterr().out)
    assert at60["settings"] == {"max_depth": 1, "shadow_samples": 1} and at60["infeasible"]
    assert at60["fps_target"] == 60.0 and at60["fps"] == 60.0 and at60["meets_fps"] is True
    assert at60["power_w"] == pytest.approx(0.5 + (6.5 - 0.5) * 2, rel=1e-3)  # view 5: 1.5 + 5 W at 30 fps
    with pytest.raises(SystemExit):
        cli.main([*args, "--fps", "0"])
    (tmp_path / "old").mkdir()
    old = _store_file(tmp_path / "old", frame_times=[0.005, 0.01, 0.02, 0.1])
    assert cli.main(["query", str(old), *args[2:], "--fps", "60"]) != 0
    assert "static power" in capsys.readouterr().err


def test_query_takes_the_priority_and_prints_it(tmp_path, capsys) -> None:
    """--priority reaches the lookup (its result names it) and is printed; a missed frame rate under
    "budget" says the budget came first; a bad value is refused by argparse; the default is frame rate
    first."""
    f = _store_file(tmp_path, frame_times=[0.05, 0.06, 0.08, 0.1], static_power_w=0.5)  # all miss 30 fps
    args = ["query", str(f), "--position", "1", "1", "1", "--direction", "0", "0", "-1", "--error-budget",
            "0.03"]
    assert cli.main([*args, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["priority"] == "frame_rate"
    assert cli.main([*args, "--json", "--priority", "budget", "--fps", "12"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["priority"] == "budget" and out["fps_target"] == 12.0 and out["meets_fps"] is True
    assert cli.main([*args, "--priority", "budget"]) == 0
    text = capsys.readouterr().out
    assert "priority: Budget first" in text and "the budget comes first" in text
    assert cli.main(args) == 0
    text = capsys.readouterr().out
    assert "priority: Frame rate first" in text and "no setting of this view keeps up" in text
    with pytest.raises(SystemExit):
        cli.main([*args, "--priority", "speed"])
    assert "invalid choice: 'speed'" in capsys.readouterr().err


def test_the_progress_bar_shows_the_whole_runs_fraction(monkeypatch, capsys) -> None:
    """Every view is done while the display pricing runs: the bar shows the run's fraction, not 9/9."""
    from service.optimize import Progress

    monkeypatch.setenv("RENDER_BUDGET_BAR", "1")
    cli._Bar(True)(Progress(views_done=9, views_planned=9, phase="price at display resolution", fraction=0.5))
    assert f"[{'#' * 15}{'.' * 15}] 9/9 views" in capsys.readouterr().err
