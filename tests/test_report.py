"""Table 3 summaries and the report folder."""

from __future__ import annotations

import csv
import json

import pytest

from service.report import FrameRecord, PathReport, table3_markdown, write_report


def _records() -> list[FrameRecord]:
    recs = []
    for f in range(4):
        t = f / 30
        recs.append(FrameRecord("maximum", f, t, 0, power_w=2.0, error=0.0))
        recs.append(FrameRecord("minimum", f, t, 1, power_w=1.0, error=0.1 + 0.01 * f))
        recs.append(FrameRecord("ours-error", f, t, 2, power_w=1.2 if f < 3 else 1.6, error=0.01 * f))
    return recs


def test_summary_matches_hand_computed_values() -> None:
    report = PathReport("toy", _records(), budgets={"ours-error": ("error", 0.015)})
    rows = {r.mode: r for r in report.summarize()}
    assert rows["maximum"].power_saving == pytest.approx(0.0)
    assert rows["minimum"].power_saving == pytest.approx(0.5)
    assert rows["minimum"].mean_error == pytest.approx(0.115)
    assert rows["ours-error"].mean_power_w == pytest.approx(1.3)
    assert rows["ours-error"].power_saving == pytest.approx(0.35)
    # errors 0, 0.01, 0.02, 0.03 against a 0.015 budget: half the frames keep it
    assert rows["ours-error"].budget_kept == pytest.approx(0.5)
    assert rows["maximum"].budget_kept is None
    assert "| ours-error | error <= 0.015 | 4 |" in table3_markdown(report.summarize())


def test_report_needs_the_reference_mode() -> None:
    recs = [r for r in _records() if r.mode != "maximum"]
    with pytest.raises(ValueError, match="maximum"):
        PathReport("toy", recs).summarize()


def test_non_finite_figures_are_refused() -> None:
    with pytest.raises(ValueError, match="power_w"):
        FrameRecord("maximum", 0, 0.0, 0, power_w=float("nan"), error=0.0)


def test_write_report_produces_a_readable_folder(tmp_path) -> None:
    budgets = {"ours-error": ("error", 0.015)}
    report = PathReport("toy", _records(), budgets=budgets, meta={"profile": "mobile"})
    paths = write_report(report, tmp_path / "rep")
    text = paths["report"].read_text()
    assert "| minimum |" in text and "profile: mobile" in text
    with paths["csv"].open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12 and {r["mode"] for r in rows} == {"maximum", "minimum", "ours-error"}
    summary = json.loads(paths["summary"].read_text())
    assert [m["mode"] for m in summary["modes"]] == ["maximum", "minimum", "ours-error"]
    for key in ("power_plot", "error_plot"):
        assert paths[key].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
