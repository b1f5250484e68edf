"""The batch script's usage text is runnable: every example in `python -m addon.batch --help` parses."""

from __future__ import annotations

import shlex

from addon import batch


def test_every_usage_example_parses() -> None:
    examples = [line.split("#")[0] for line in (batch.__doc__ or "").splitlines()
                if line.startswith("    ") and ("addon.batch" in line or "addon/batch.py" in line)]
    assert len(examples) >= 3
    for line in examples:
        words = shlex.split(line)
        argv = words[words.index("--") + 1:] if "--" in words else words[words.index("addon.batch") + 1:]
        args = batch.parser().parse_args(argv)  # exits (SystemExit) on an unrecognised argument
        assert args.command in batch.COMMANDS
