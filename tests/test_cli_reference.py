"""docs/reference/cli.md is the page vibr.cli.reference generates from the parsers: a test
fails when an option changes and the page is not generated again."""

import argparse
import difflib
from pathlib import Path

import pytest

from vibr.cli import build_parser
from vibr.cli.reference import COMMAND, WIDTH, markdown, subcommands, usage

PAGE = Path(__file__).resolve().parents[1] / "docs" / "reference" / "cli.md"


def check_page(committed: str, generated: str) -> None:
    """Fail, with the command that writes the page again and the first differences, when the
    committed page is not the generated one."""
    if committed != generated:
        diff = "".join(list(difflib.unified_diff(committed.splitlines(True), generated.splitlines(True),
                                                 "committed", "generated"))[:40])
        raise AssertionError(f"{PAGE.relative_to(PAGE.parents[2])} is stale: run `PYTHONPATH=src {COMMAND}`\n{diff}")


def test_page_is_generated_from_the_parsers():
    check_page(PAGE.read_text(encoding="utf-8"), markdown())


def test_a_new_flag_makes_the_page_stale():
    parser = build_parser()
    subcommands(parser)["render"].add_argument("--extra-flag", metavar="X", help="a flag the page does not have")
    generated = markdown(parser)
    assert "`--extra-flag`" in generated and "[--extra-flag X]" in generated
    with pytest.raises(AssertionError, match=r"stale: run `PYTHONPATH=src python3 -m vibr\.cli\.reference >") as err:
        check_page(PAGE.read_text(encoding="utf-8"), generated)
    assert "+| `--extra-flag` | `X` |" in str(err.value)


def test_every_subcommand_and_option_is_on_the_page():
    parser = build_parser()
    page = markdown(parser)
    for name, sub in subcommands(parser).items():
        assert f"### vibr {name}\n" in page and usage(sub) in page
        for action in sub._actions:
            if action.help is not argparse.SUPPRESS and action.option_strings and action.dest != "help":
                assert f"`{action.option_strings[-1]}`" in page, (name, action.option_strings)


def test_page_does_not_depend_on_the_terminal(monkeypatch):
    wide = markdown()
    monkeypatch.setenv("COLUMNS", "30")
    assert markdown() == wide
    parser = build_parser()
    lines = [line for p in [parser, *subcommands(parser).values()] for line in usage(p).splitlines()]
    assert len(lines) > 10 and all(len(line) <= WIDTH or line.count("[") == 1 for line in lines)  # one long option
