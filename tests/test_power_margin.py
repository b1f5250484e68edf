"""The lookup's power margin (``service.options.QUERY_POWER_MARGIN``): a power budget searched that share
lower, for the power prediction's own error near the budget (a pick predicted 1-2 % under a budget that
measures over it), while a budget is still kept or broken against its own value. Property tests over
random stores (those of ``test_store_lookup``) for both margins, the error margin's included; the
two-tier store of ``test_lookup_priority``, playback's memo, the main job's spec and report note, and
the command line for the power margin (``test_error_margin`` has the error margin's)."""

from __future__ import annotations

import dataclasses
import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.test_lookup_priority import _two_tier_store
from tests.test_store_lookup import budgets, orientations, positions, stores

WHERE, LOOK = (5.0, 5.0, 5.0), (1.0, 0.0, 0.0)


def _without_query(hit) -> dict:
    """A lookup result's choice, without the fields that only echo the query."""
    return {k: v for k, v in dataclasses.asdict(hit).items()
            if k not in ("budget", "error_margin", "power_margin")}


@pytest.mark.parametrize("kind", ["error", "power"])
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_margin_answers_as_the_lowered_budget_and_leaves_the_other_kind_of_budget_alone(
        kind: str, data: st.DataObject) -> None:
    """An error margin is subtracted from an error budget, a power margin taken as a share off a power
    budget: the answer, and every point the filter may show, are those of the lowered budget."""
    store = data.draw(stores())
    margin = data.draw(st.sampled_from([0.0, 0.002, 0.01, 0.05, 0.3, 0.5]))
    priority = data.draw(st.sampled_from(["frame_rate", "budget"]))
    name, key = f"{kind}_margin", f"{kind}_budget"
    for _ in range(6):
        pose = data.draw(orientations())
        where = data.draw(positions(store))
        budget = data.draw(budgets(store))
        try:
            plain = store.lookup(where, **pose, **budget, priority=priority)
        except ValueError:  # a degenerate pose (test_store_lookup checks the message)
            continue
        hit = store.lookup(where, **pose, **budget, priority=priority, **{name: margin})
        if key not in budget:  # a margin is for its own kind of budget only
            assert hit == plain and getattr(hit, name) == 0.0
            continue
        value = budget[key]
        searched = value - margin if kind == "error" else value * (1.0 - margin)
        lowered = store.lookup(where, **pose, **{key: searched}, priority=priority)
        assert _without_query(hit) == _without_query(lowered)
        assert hit.budget == value and getattr(hit, name) == margin
        assert hit.error_margin + hit.power_margin == margin  # the other kind's stays 0
        assert hit.searched_budget == pytest.approx(searched)
        points = store.budget_points(hit)
        assert [p.packed for p in points] == [p.packed for p in store.budget_points(lowered)]
        if not hit.infeasible:  # every point the filter may show lies under the lowered budget
            assert all((p.error if kind == "error" else p.power_w) <= searched * (1 + 1e-12) for p in points)
        if margin == 0.0:
            assert hit == plain


def test_a_margin_takes_the_next_cheaper_setting_and_the_cheapest_when_none_is_under_it() -> None:
    s = _two_tier_store()
    # 0.62 W: the real-time setting at 0.6 W (error 0.05) keeps it ...
    plain = s.lookup(WHERE, direction=LOOK, power_budget=0.62)
    assert plain.indices == (1, 1, 2) and not plain.infeasible and plain.power_w == 0.6
    # ... but not 5 % under it (0.589 W): the next cheaper real-time setting, 0.3 W at error 0.2
    hit = s.lookup(WHERE, direction=LOOK, power_budget=0.62, power_margin=0.05)
    assert hit.indices == (2, 1, 3) and not hit.infeasible and hit.power_w == 0.3
    assert hit.budget == 0.62 and hit.searched_budget == pytest.approx(0.589)
    assert all(p.power_w <= 0.589 for p in s.budget_points(hit))
    # nothing 20 % under 0.22 W (0.176): flagged, the cheapest setting, as when nothing keeps the budget
    none = s.lookup(WHERE, direction=LOOK, power_budget=0.22, power_margin=0.2)
    assert none.infeasible and none.power_w == 0.2
    assert not s.lookup(WHERE, direction=LOOK, power_budget=0.22).infeasible
    # an error budget ignores it
    assert s.lookup(WHERE, direction=LOOK, error_budget=0.06, power_margin=0.2) == s.lookup(
        WHERE, direction=LOOK, error_budget=0.06)
    for bad in (-0.001, 0.6, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="power_margin"):
            s.lookup(WHERE, direction=LOOK, power_budget=0.62, power_margin=bad)


def test_playback_keeps_answers_for_each_power_margin_apart() -> None:
    """The playback driver memoises lookups on their inputs: the margin is one of them."""
    from addon.core.playback_logic import PlaybackDriver, predicted_path_summary
    from service.store.camera import look_matrix

    s = _two_tier_store()
    driver = PlaybackDriver(s, 0.0)
    m = look_matrix(WHERE, LOOK).tolist()
    first = driver.step(m, 0.69, 16 / 9, 0.0, "POWER", 0.62)
    margin = driver.step(m, 0.69, 16 / 9, 0.0, "POWER", 0.62, power_margin=0.05)
    assert first.active_indices == (1, 1, 2) and margin.target_indices == (2, 1, 3)
    assert driver.memo_hits == 0
    with pytest.raises(ValueError, match="unknown query options"):
        driver.step(m, 0.69, 16 / 9, 0.0, "POWER", 0.62, margin=0.05)

    frames = [dataclasses.make_dataclass("F", ["matrix_world", "vfov", "aspect"])(
        look_matrix(WHERE, LOOK), 0.69, 16 / 9)]
    plain = predicted_path_summary(s, frames, "POWER", 0.62)
    kept = predicted_path_summary(s, frames, "POWER", 0.62, power_margin=0.05)
    assert kept["mean_power_w"] == pytest.approx(0.3) and plain["mean_power_w"] == pytest.approx(0.6)


def test_the_main_jobs_spec_and_report_say_the_power_margin() -> None:
    from addon.core.campaign import CampaignSpec, lookup_heading, lookup_note
    from addon.core.evaluate_path import EvalSpec

    s = _two_tier_store()
    spec = CampaignSpec(scene_id="s", resolution=(64, 36), power_margin=0.05)
    assert spec.query == {"fps": None, "priority": "frame_rate", "error_margin": 0.0, "power_margin": 0.05}
    assert lookup_heading(spec, s).endswith("frame rate first, the power budget with a 5 % margin")
    note = lookup_note(spec, s)
    assert "at most 95 % of its budget" in note and "against the budget itself" in note
    plain = dataclasses.replace(spec, power_margin=0.0)
    assert "margin" not in lookup_heading(plain, s) and "margin" not in lookup_note(plain, s)
    with pytest.raises(ValueError, match="power_margin"):
        CampaignSpec(scene_id="s", resolution=(64, 36), power_margin=0.9)
    # each evaluation pass takes the same options (keyword-only, after its own positional fields)
    es = EvalSpec("s", "mobile", (64, 36), "POWER", 3.0, **spec.query)
    assert es.query == spec.query
    with pytest.raises(ValueError, match="power_margin"):
        EvalSpec("s", "mobile", (64, 36), "POWER", 3.0, power_margin=-0.1)


def test_the_query_command_takes_a_power_margin(tmp_path, capsys) -> None:
    from service.cli import main

    s = _two_tier_store()
    path = tmp_path / "store.json"
    path.write_text(s.to_json(), encoding="utf-8")
    base = ["query", str(path), "--position", *map(str, WHERE), "--direction", *map(str, LOOK),
            "--power-budget", "0.62"]
    assert main([*base, "--power-margin", "0.05", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["indices"] == [2, 1, 3] and got["power_margin"] == 0.05 and got["error_margin"] == 0.0
    assert main([*base, "--power-margin", "0.05"]) == 0
    assert "5 % of the budget (settings searched under 0.589 W)" in capsys.readouterr().out
    assert main([*base, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["indices"] == [1, 1, 2]
    with pytest.raises(SystemExit):
        main([*base, "--power-margin", "0.7"])
