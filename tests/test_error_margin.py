"""The lookup's error margin (``service.options.QUERY_ERROR_MARGIN``): an error budget searched that much
lower, for the prediction's own error near the budget, while a budget is still kept or broken against its
own value. The two-tier store of ``test_lookup_priority`` (a margin that moves budget first to a slow
setting), playback's memo, the main job's spec and report note, and the command line; the property test
over random stores is ``test_power_margin``'s, for both margins."""

from __future__ import annotations

import dataclasses
import json

import pytest

from tests.test_lookup_priority import _two_tier_store

WHERE, LOOK = (5.0, 5.0, 5.0), (1.0, 0.0, 0.0)


def test_a_margin_moves_budget_first_to_a_slow_setting_and_frame_rate_first_to_its_most_accurate() -> None:
    s = _two_tier_store()
    # budget 0.06: a real-time setting at 0.05 keeps it ...
    plain = s.lookup(WHERE, direction=LOOK, error_budget=0.06, priority="budget")
    assert plain.indices == (1, 1, 2) and plain.meets_fps and not plain.infeasible
    # ... but not 0.015 under it: budget first takes the cheapest slow setting under 0.045
    hit = s.lookup(WHERE, direction=LOOK, error_budget=0.06, priority="budget", error_margin=0.015)
    assert hit.indices == (1, 0, 1) and hit.meets_fps is False and not hit.infeasible
    assert hit.budget == 0.06 and hit.searched_budget == pytest.approx(0.045)
    assert [p.indices for p in s.budget_points(hit)] == [(1, 0, 1), (0, 0, 0)]
    # frame rate first keeps the rate: the most accurate real-time setting, flagged (nothing under 0.045)
    rate_first = s.lookup(WHERE, direction=LOOK, error_budget=0.06, error_margin=0.015)
    assert rate_first.indices == (1, 1, 2) and rate_first.infeasible and rate_first.meets_fps
    # a power budget ignores it
    assert s.lookup(WHERE, direction=LOOK, power_budget=0.9, error_margin=0.015) == s.lookup(
        WHERE, direction=LOOK, power_budget=0.9)
    for bad in (-0.001, 0.6, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="error_margin"):
            s.lookup(WHERE, direction=LOOK, error_budget=0.06, error_margin=bad)


def test_playback_keeps_answers_for_each_margin_apart() -> None:
    """The playback driver memoises lookups on their inputs: the margin is one of them."""
    from addon.core.playback_logic import PlaybackDriver, predicted_path_summary
    from service.store.camera import look_matrix

    s = _two_tier_store()
    driver = PlaybackDriver(s, 0.0)
    m = look_matrix(WHERE, LOOK).tolist()
    first = driver.step(m, 0.69, 16 / 9, 0.0, "ERROR", 0.06, priority="budget")
    margin = driver.step(m, 0.69, 16 / 9, 0.0, "ERROR", 0.06, priority="budget", error_margin=0.015)
    assert first.active_indices == (1, 1, 2) and margin.target_indices == (1, 0, 1)
    assert margin.meets_fps is False and driver.memo_hits == 0

    frames = [dataclasses.make_dataclass("F", ["matrix_world", "vfov", "aspect"])(
        look_matrix(WHERE, LOOK), 0.69, 16 / 9)]
    plain = predicted_path_summary(s, frames, "ERROR", 0.06, priority="budget")
    kept = predicted_path_summary(s, frames, "ERROR", 0.06, priority="budget", error_margin=0.015)
    assert kept != plain


def test_the_main_jobs_spec_and_report_say_the_margin() -> None:
    from addon.core.campaign import CampaignSpec, lookup_heading, lookup_note

    s = _two_tier_store()
    spec = CampaignSpec(scene_id="s", resolution=(64, 36), error_budget=0.02, error_margin=0.002)
    assert spec.query == {"fps": None, "priority": "frame_rate", "error_margin": 0.002, "power_margin": 0.0}
    assert "0.002 margin" in lookup_heading(spec, s)
    note = lookup_note(spec, s)
    assert "within 0.018" in note and "against 0.02" in note
    plain = dataclasses.replace(spec, error_margin=0.0)
    assert "margin" not in lookup_heading(plain, s) and "margin" not in lookup_note(plain, s)
    with pytest.raises(ValueError, match="error_margin"):
        CampaignSpec(scene_id="s", resolution=(64, 36), error_margin=-1.0)


def test_the_query_command_takes_a_margin(tmp_path, capsys) -> None:
    from service.cli import main

    s = _two_tier_store()
    path = tmp_path / "store.json"
    path.write_text(s.to_json(), encoding="utf-8")
    base = ["query", str(path), "--position", *map(str, WHERE), "--direction", *map(str, LOOK),
            "--error-budget", "0.06", "--priority", "budget"]
    assert main([*base, "--error-margin", "0.015", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["indices"] == [1, 0, 1] and got["error_margin"] == 0.015 and got["meets_fps"] is False
    assert main([*base, "--error-margin", "0.015"]) == 0
    assert "settings searched under 0.045" in capsys.readouterr().out
    assert main([*base, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["indices"] == [1, 1, 2]
    with pytest.raises(SystemExit):
        main([*base, "--error-margin", "-0.01"])

