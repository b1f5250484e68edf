"""The batch script's usage is runnable as written: every example in `python -m addon.batch --help` and in
the README parses, and the usage text names the options that say where jobs run as the parser has them."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from addon import batch

README = Path(__file__).resolve().parent.parent / "README.md"


def _argv(line: str) -> list[str]:
    words = shlex.split(line.split("#")[0])
    return words[words.index("--") + 1:] if "--" in words else words[words.index("addon.batch") + 1:]


def _readme_examples() -> list[str]:
    """Command lines of the README's code blocks that run the batch script (continuations joined)."""
    joined = re.sub(r"\\\n\s*", " ", README.read_text(encoding="utf-8"))
    blocks = re.findall(r"```\n(.*?)```", joined, flags=re.S)
    return [line for block in blocks for line in block.splitlines()
            if "addon.batch" in line or "addon/batch.py" in line]


def _docstring_examples() -> list[str]:
    return [line for line in (batch.__doc__ or "").splitlines()
            if line.startswith("    ") and ("addon.batch" in line or "addon/batch.py" in line)]


def test_every_usage_example_parses() -> None:
    examples = _docstring_examples() + _readme_examples()
    assert len(_docstring_examples()) >= 3 and len(_readme_examples()) >= 3
    for line in examples:
        args = batch.parser().parse_args(_argv(line))  # exits (SystemExit) on an unrecognised argument
        assert args.command in batch.COMMANDS, line


def test_the_usage_text_lists_where_jobs_run_as_the_parser_has_it() -> None:
    group = next(g for g in batch.parser()._action_groups if g.title and g.title.startswith("where jobs run"))
    options = {s for action in group._group_actions for s in action.option_strings}
    listed = re.search(r"Where jobs run \(([^)]*)\)", " ".join((batch.__doc__ or "").split()))
    assert listed is not None
    assert set(listed.group(1).replace(",", " ").split()) == options


def test_the_removed_serve_flag_is_refused() -> None:
    """Jobs run on this computer by default now: the old `--serve` is an error, not silently ignored."""
    with pytest.raises(SystemExit):
        batch.parser().parse_args(["--serve", "optimize"])


def test_a_job_is_given_up_on_a_stall_not_after_an_hour() -> None:
    """A heavy scene's optimisation runs for hours while it progresses: no total limit by default, a stall
    limit instead; limits that are not positive finite seconds are refused."""
    from service.options import JOB_STALL_TIMEOUT_S

    args = batch.parser().parse_args(["optimize"])
    assert args.timeout is None and args.stall_timeout == JOB_STALL_TIMEOUT_S
    args = batch.parser().parse_args(["--timeout", "7200", "--stall-timeout", "600", "optimize"])
    assert (args.timeout, args.stall_timeout) == (7200.0, 600.0)
    for flag in ("--timeout", "--stall-timeout"):
        for bad in ("0", "-1", "nan", "inf", "soon"):
            with pytest.raises(SystemExit):
                batch.parser().parse_args([flag, bad, "optimize"])
