"""The evaluation campaign's pure parts (addon.core.campaign): sizes, frame choice, budgets, targets and the
report's sections. The whole campaign runs against a real service in test_demo.py and
test_addon_service.py (the demo and the add-on's batch evaluate)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from addon.core import campaign, campaign_targets, report


def test_parse_size_accepts_wxh_and_reports_bad_text() -> None:
    assert campaign.parse_size("64x36") == (64, 36)
    assert campaign.parse_size("128X72") == (128, 72)
    for bad in ("64", "64x", "ax36", "64x36x2"):
        with pytest.raises(ValueError, match="expected WxH"):
            campaign.parse_size(bad)
    with pytest.raises(ValueError, match="at least 8x8"):
        campaign.parse_size("4x4")
    assert campaign.parse_size("4x4", minimum=4) == (4, 4)
    # argparse shows the message itself (not "invalid parse_size value")
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=campaign.parse_size)
    assert issubclass(campaign.SizeError, argparse.ArgumentTypeError)
    assert ap.parse_args(["--size", "16x9"]).size == (16, 9)


@given(n=st.integers(1, 5000), about=st.integers(-1, 400))
def test_frame_step_evaluates_about_the_asked_number(n: int, about: int) -> None:
    step = campaign.frame_step(n, about)
    frames = range(0, n, step)
    if about <= 0:
        assert step == 1
    else:
        assert len(frames) <= max(about, 1) or step == 1
        assert step == 1 or len(range(0, n, step - 1)) > about  # the smallest step that fits


@given(n=st.integers(1, 5000), count=st.integers(0, 12))
def test_sample_picks_spread_from_first_to_last(n: int, count: int) -> None:
    picks = campaign.sample_picks(n, count)
    assert picks == sorted(set(picks)) and all(0 <= i < n for i in picks)
    if count == 0:
        assert picks == []
    else:
        assert picks[0] == 0 and len(picks) <= count
        assert count == 1 or picks[-1] == n - 1


def test_spec_rejects_bad_budgets_and_counts() -> None:
    ok = {"scene_id": "s", "resolution": (64, 36)}
    campaign.CampaignSpec(**ok)
    for bad, match in (({"error_budget": 1.5}, "error budget"), ({"power_budget": 0.0}, "power budget"),
                       ({"power_budget_from": "guess"}, "presets or store"),
                       ({"power_fraction": 1.2}, "fraction"), ({"frame_step": 0}, "frame_step"),
                       ({"priority": "speed"}, "priority must be one of"), ({"fps": 0.0}, "fps must be in")):
        with pytest.raises(ValueError, match=match):
            campaign.CampaignSpec(**ok, **bad)


def _rows() -> list[report.FrameRow]:
    rows = []
    for i in range(4):
        t = i / 30
        rows += [report.FrameRow(i, t, "max", 10.0, 0.0), report.FrameRow(i, t, "max_mid", 6.0, 0.01),
                 report.FrameRow(i, t, "mid_min", 3.0, 0.05), report.FrameRow(i, t, "min", 2.0, 0.3),
                 report.FrameRow(i, t, "ours_power", 5.0 + (i == 3), 0.02, budget_kept=i != 3),
                 report.FrameRow(i, t, "ours_error", 4.0, 0.01, budget_kept=True)]
    return rows


def test_budget_from_presets_lies_between_min_and_max() -> None:
    budget, reason = campaign.budget_from_presets(_rows(), 0.4)
    assert budget == pytest.approx(2.0 + 0.4 * 8.0)
    assert "(2.000 W)" in reason and "(10.000 W)" in reason
    with pytest.raises(ValueError, match="fraction"):
        campaign.budget_from_presets(_rows(), -0.1)


def test_targets_follow_the_measured_summaries() -> None:
    targets = campaign_targets.check_targets(report.summarise(_rows()))
    assert targets["error_budget_saving"] == pytest.approx(0.6)
    assert targets["error_budget_saving_met"] is True
    assert targets["power_budget_error_ratio_vs_min"] == pytest.approx(15.0)
    assert targets["power_budget_kept"] == pytest.approx(0.75) and targets["power_budget_kept_met"] is False
    assert targets["all_met"] is False
    lines = campaign_targets.target_lines(targets, 50 * 1024)
    assert len(lines) == 4 and lines[2].endswith("MISSED") and lines[3].endswith("MISSED")
    assert "60.0 % power saved" in lines[0] and lines[0].endswith("met")
    # each share with its frames and how sure it is (Wilson 95 %, tests/test_stats.py)
    assert targets["power_budget_kept_frames"] == [3, 4] and targets["error_budget_kept_frames"] == [4, 4]
    assert lines[2].startswith("- budget kept: power 3/4 (75 %; 95 % interval 30-95 %), "
                               "error 4/4 (100 %; 95 % interval 51-100 %) of frames")


def test_report_takes_sections_and_is_written_once(tmp_path: Path) -> None:
    sections = [report.Section("First", ("- a", "- b")), report.Section("Second", ("text",))]
    written = report.write_report(tmp_path, _rows(), title="t", budget=[("POWER", 6.0), ("ERROR", 0.02)],
                                  notes=["a note"], sections=sections, plot=False)
    text = Path(written["report"]).read_text()
    assert text.index("| Avg. Power (W)") < text.index("- a note") < text.index("## First")
    assert text.index("## First\n\n- a\n- b") < text.index("## Second\n\ntext")
    assert math.isclose(float(text.split("power <= ")[1].split(" W")[0]), 6.0)


def test_reports_show_fps_per_mode_and_which_presets_are_real_time(tmp_path: Path) -> None:
    rows = []
    for i in range(4):
        t = i / 4  # times the CSV keeps exactly
        rows += [report.FrameRow(i, t, "max", 0.7, 0.0, fps=1.3, deadline_met=False),
                 report.FrameRow(i, t, "max_mid", 0.8, 0.01, fps=8.0 + i, deadline_met=False),
                 report.FrameRow(i, t, "mid_min", 0.45, 0.05, fps=30.0 if i else 25.0, deadline_met=i > 0),
                 report.FrameRow(i, t, "min", 0.27, 0.3, fps=30.0, deadline_met=True),
                 report.FrameRow(i, t, "ours_error", 0.4, 0.01, budget_kept=True, fps=30.0,
                                 deadline_met=True)]
    s = {x.mode: x for x in report.summarise(rows)}
    assert s["max_mid"].mean_fps == pytest.approx(9.5) and s["max_mid"].min_fps == 8.0
    assert s["mid_min"].real_time_fraction == 0.75 and s["mid_min"].real_time is False
    assert s["min"].real_time is True and s["max"].real_time is False
    md = report.table3_markdown(report.summarise(rows)).splitlines()
    assert md[3].startswith("| Avg. fps (reached) | 30 | 1.3 | 9.5 | 28.8 | 30 |")  # Ours first
    assert md[4].startswith("| Frames at target fps | 100 % | 0 % | 0 % | 75 % | 100 % |")
    notes = report.real_time_notes(report.summarise(rows), 30.0, "on the `mobile` profile at 1280x720")
    assert notes[0].startswith("Real time (30 fps) on the `mobile` profile at 1280x720: Min; not real time: "
                               "Max (1.3 fps on average, 0 % of frames at the target); Max-Mid")
    assert "Max preset is not real time here: it delivers 1.3 fps, not 30" in notes[1]
    # the CSV keeps the frame rates; a CSV written before them reads with the frame rate unknown
    assert report.read_csv(report.write_csv(tmp_path / "a.csv", rows)) == rows
    old = tmp_path / "old.csv"
    old.write_text("frame,time_s,mode,power_w,error,settings,budget_kept,predicted_power_w,predicted_error\n"
                   "0,0.0,max,8.8,0.0,,,,\n", encoding="utf-8")
    (row,) = report.read_csv(old)
    assert row.fps is None and row.deadline_met is None
    assert report.summarise([row])[0].mean_fps is None and report.real_time_notes(
        report.summarise([row]), 30.0, "") == []
    assert "Avg. fps" not in report.table3_markdown(report.summarise([row]))
    with pytest.raises(ValueError, match="frame rate"):
        report.FrameRow(0, 0.0, "max", 1.0, 0.0, fps=0.0)
    with pytest.raises(ValueError, match="frame rate"):
        report.FrameRow(0, 0.0, "ours_power", 1.0, 0.0, predicted_fps=math.inf)


def test_a_store_priced_at_a_display_size_is_measured_there_and_labelled() -> None:
    """Table 3 checks what the store promises: renders and power at the size its figures are for; a store
    with preview figures is measured at its search size with power scaled to the path's."""
    import dataclasses

    import numpy as np

    from service.camera_path import CameraFrame, CameraPath
    from tests.test_pareto_store import _store

    path = CameraPath((CameraFrame(0.0, np.eye(4), 0.8, (1280, 720)),), fps=30.0)
    store = _store()
    preview = dataclasses.replace(store, meta={"display_pricing": "preview", "figures_resolution": [64, 36]})
    display = dataclasses.replace(store, meta={"display_pricing": "full:ssim",
                                               "figures_resolution": [320, 180]})
    assert campaign.measurement_sizes(preview.to_json(), (64, 36), path) == ((64, 36), (1280, 720))
    assert campaign.measurement_sizes(store.to_json(), (64, 36), path) == ((64, 36), (1280, 720))
    assert campaign.measurement_sizes(display.to_json(), (64, 36), path) == ((320, 180), (320, 180))

    def note(resolution: tuple[int, int], power: tuple[int, int]) -> str:
        return campaign.size_note(campaign.CampaignSpec("s", resolution, power_resolution=power), path)

    assert "preview resolution" in note((64, 36), (1280, 720))
    assert "1280x720 is not measured here" in note((320, 180), (320, 180))
    assert "the path's own size" in note((1280, 720), (1280, 720))


def test_the_query_options_reach_the_budget_modes_lookups_and_the_report() -> None:
    """CampaignSpec's frame-rate target and priority reach every lookup of the budget modes (the frames
    playback would show, through the same driver), the measured frame rate and Table 3's heading."""
    import numpy as np

    from addon.core.evaluate_path import EvalSpec, filtered_frames, measurement_fps
    from service.camera_path import CameraPath
    from tests.addon_support import synthetic_store

    store = synthetic_store(timed=True)
    store.meta["static_power_w"] = 0.2
    ang = np.linspace(0.0, 1.5, 8)
    path = CameraPath.from_positions([(3 * np.cos(a), 3 * np.sin(a), 1.0) for a in ang],
                                     [(-np.cos(a), -np.sin(a), -0.2) for a in ang], vfov=0.69,
                                     resolution=(64, 36), fps=30.0)
    shown = filtered_frames(store, path, range(8), "POWER", 3.0, 0.5, {"fps": 12.0, "priority": "budget"})
    assert {(pf.priority, pf.fps_target) for pf in shown.values()} == {("budget", 12.0)}
    assert {pf.priority for pf in filtered_frames(store, path, range(8), "POWER", 3.0, 0.5).values()} == {
        "frame_rate"}
    with pytest.raises(ValueError, match="priority"):
        EvalSpec("s", "mobile", (64, 36), "POWER", 3.0, priority="speed")
    assert measurement_fps(None, path) == 30.0 and measurement_fps(12.0, path) == 12.0
    spec = campaign.CampaignSpec("s", (64, 36), fps=12.0, priority="budget")
    assert campaign.lookup_heading(spec, store) == ("Table 3: budget modes looked up for 12 fps (asked for), "
                                                    "budget first")
    assert campaign.lookup_heading(campaign.CampaignSpec("s", (64, 36)), store).endswith(
        "24 fps (the store's own), frame rate first")
    assert "Priority: budget first" in campaign.lookup_note(spec, store)
    assert "max quality alone" not in campaign.lookup_note(spec, store)
    store.meta["slow_points"] = 1  # a store that priced max quality alone in its slow tiers says so
    assert "max quality alone among the settings that miss 12 fps" in campaign.lookup_note(spec, store)
    assert "max quality alone" not in campaign.lookup_note(campaign.CampaignSpec("s", (64, 36)), store)
    assert "asked for 12 fps" in campaign.size_note(spec, path)
    with pytest.raises(ValueError, match="static power"):  # a target the store cannot answer
        campaign.lookup_heading(spec, synthetic_store(timed=True))
