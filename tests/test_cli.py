"""Command line: query a real store; argument validation; serve flags."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from service import cli
from service.store import Frontier, ParetoStore, StoredParameter, pack_indices


def _store_file(tmp_path):
    params = (StoredParameter("max_depth", (0, 1, 2, 3), 3),
              StoredParameter("shadow_samples", (0, 1, 4, 16), 3))
    fr = [Frontier.from_points([pack_indices([k, k]) for k in range(4)], [0.3, 0.1, 0.02, 0.0],
                               [1.0 + v, 1.5 + v, 2.0 + v, 3.0 + v]) for v in range(6)]
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)])
    views = np.tile(np.arange(6), (8, 1))
    store = ParetoStore(params, np.zeros(3), 4.0, 0, np.array([-1]), corners, views, fr,
                        vfov=math.radians(40), aspect=1.5)
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
])
def test_bad_arguments(argv) -> None:
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2


def test_serve_flags() -> None:
    args = cli.build_parser().parse_args(["serve", "--host", "0.0.0.0", "--port", "9000", "--data-dir", "d",
                                          "--dask-scheduler", "tcp://h:8786", "--token", "t"])
    assert (args.host, args.port, str(args.data_dir), args.dask_scheduler, args.token) == (
        "0.0.0.0", 9000, "d", "tcp://h:8786", "t")
    d = cli.build_parser().parse_args(["serve"])
    assert (d.host, d.port, d.token) == ("127.0.0.1", 8765, None)
