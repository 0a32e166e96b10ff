"""The command line explains itself: every subcommand has a one-line description, every option a help
text, and no help output shows reStructuredText markup (raw double back-ticks)."""
import argparse

import pytest

from mechanism.cli import build_parser

PARSER = build_parser()
SUBPARSERS = next(a for a in PARSER._actions if isinstance(a, argparse._SubParsersAction))
NAMES = sorted(SUBPARSERS.choices)


def test_every_subcommand_is_listed_with_a_one_line_description():
    helps = {a.dest: a.help for a in SUBPARSERS._choices_actions}
    assert set(helps) == set(NAMES)
    assert {"run", "reproduce", "stepsize-study", "advise", "ssp-generate", "ssp-pack", "ssp-simulate"} <= set(NAMES)
    for name, text in helps.items():
        assert text and "\n" not in text, name
    top = PARSER.format_help()
    assert all(name in top for name in NAMES) and "``" not in top


@pytest.mark.parametrize("name", NAMES)
def test_every_option_has_help_and_no_raw_markup(name):
    sub = SUBPARSERS.choices[name]
    assert sub.description, f"{name} has no description"
    missing = [a.option_strings for a in sub._actions if a.option_strings and not a.help]
    assert not missing, f"{name}: options without help text {missing}"
    assert "``" not in sub.format_help(), name


@pytest.mark.parametrize("code, expected", [("0", 0), ("None", 0), ("3", 3), ("'a message'", 1)])
def test_exit_now_exits_as_sys_exit_even_with_stdout_closed(code, expected):
    """``cli.exit_now`` (no module tear-down) exits with sys.exit's status, also when the process started with its
    standard output closed (``sys.stdout`` None: a reviewer's finding, it raised and exited 1)."""
    import shlex
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    script = f"from mechanism.cli import exit_now; exit_now({code})"
    done = subprocess.run(["sh", "-c", f"{shlex.quote(sys.executable)} -c {shlex.quote(script)} >&-"], cwd=root,
                          capture_output=True, text=True)
    assert done.returncode == expected, done.stderr
