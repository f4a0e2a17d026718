"""The command-line reference page (docs/reference/cli.md), generated from vibr's parsers.

``python3 -m vibr.cli.reference > docs/reference/cli.md`` writes it; tests/test_cli_reference.py
fails when the committed page differs from what this module generates. The text depends only on
the parsers: the usage lines are wrapped here at :data:`WIDTH` columns (not by argparse, whose
wrapping follows the terminal's width and the Python version).
"""

from __future__ import annotations

import argparse
import sys

from . import GLOBAL_OPTIONS, build_parser

#: The command that writes the page (printed at its top).
COMMAND = "python3 -m vibr.cli.reference > docs/reference/cli.md"
#: Columns of the usage lines.
WIDTH = 88


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands' parsers of ``parser`` by name, in the order of ``--help`` (an alias
    of a subcommand is left out: it names the same parser)."""
    out: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if all(sub is not p for p in out.values()):
                    out[name] = sub
    return out


def _shown(action: argparse.Action) -> bool:
    return action.help is not argparse.SUPPRESS and not isinstance(action, argparse._HelpAction)


def _metavar(action: argparse.Action) -> str:
    """The value an option takes as ``--help`` writes it (``K|all``, ``NEAR FAR``, ``{a,b}``)."""
    fmt = argparse.HelpFormatter("vibr")
    if action.option_strings:
        return fmt._format_args(action, fmt._get_default_metavar_for_optional(action))
    return fmt._format_args(action, fmt._get_default_metavar_for_positional(action))


def _usage_parts(parser: argparse.ArgumentParser) -> list[str]:
    """The words of ``parser``'s usage: options (in brackets unless required; a mutually
    exclusive group as one ``[a | b]``), then positionals."""
    groups = {a: g for g in parser._mutually_exclusive_groups for a in g._group_actions}
    options, positionals, done = [], [], set()
    for action in parser._actions:
        if action.help is argparse.SUPPRESS or action in done:
            continue
        if not action.option_strings:
            positionals.append("COMMAND ..." if isinstance(action, argparse._SubParsersAction) else _metavar(action))
            continue
        group = groups.get(action)
        members = [a for a in group._group_actions if a.help is not argparse.SUPPRESS] if group else [action]
        done.update(members)
        words = " | ".join(" ".join(filter(None, [a.option_strings[0], _metavar(a)])) for a in members)
        options.append(words if action.required or (group and group.required) else f"[{words}]")
    return options + positionals


def usage(parser: argparse.ArgumentParser) -> str:
    """``parser``'s usage wrapped at :data:`WIDTH` columns, continuation lines under its first
    option; a bracketed option is never split."""
    prefix = f"usage: {parser.prog} "
    lines, line = [], prefix
    for word in _usage_parts(parser):
        if len(line) + len(word) > WIDTH and line.strip() != prefix.strip():
            lines.append(line.rstrip())
            line = " " * len(prefix)
        line += word + " "
    return "\n".join(lines + [line.rstrip()])


def _cell(text: str) -> str:
    """Text for a Markdown table cell: one line; ``|``, ``*``, ``<`` escaped."""
    text = " ".join(str(text).split())
    for ch in "\\|*<":
        text = text.replace(ch, "\\" + ch)
    return text


def _code(text: str) -> str:
    return f"`{text}`".replace("|", "\\|") if text else ""


def _default(action: argparse.Action) -> str:
    d = action.default
    if d is None or d is argparse.SUPPRESS or action.nargs == 0:  # a flag's False is no default
        return ""
    return ",".join(map(str, d)) if isinstance(d, (list, tuple)) else str(d)


def _help(action: argparse.Action) -> str:
    return argparse.HelpFormatter("vibr")._expand_help(action) if action.help else ""


def _table(actions: list[argparse.Action]) -> list[str]:
    rows = ["| Option | Value | Default | Description |", "|---|---|---|---|"]
    for a in actions:
        flags = ", ".join(_code(s) for s in a.option_strings) or _code(_metavar(a))
        value = _code(_metavar(a)) if a.option_strings else ""
        rows.append(f"| {flags} | {value} | {_code(_default(a))} | {_cell(_help(a))} |")
    return rows


def _section(parser: argparse.ArgumentParser, level: int) -> list[str]:
    out = [f"{'#' * level} {parser.prog}", "", "```text", usage(parser), "```", ""]
    for paragraph in (parser.description or "").split("\n\n"):
        if paragraph.strip():
            out += [" ".join(paragraph.split()), ""]
    for group in parser._action_groups:
        actions = [a for a in group._group_actions
                   if _shown(a) and not isinstance(a, argparse._SubParsersAction)]
        if not actions:
            continue
        if group.title == GLOBAL_OPTIONS and level > 2:
            out += [f"Global options ({', '.join(_code(a.option_strings[-1]) for a in actions)}): "
                    "see [vibr](#vibr).", ""]
            continue
        out += [f"**{group.title[0].upper()}{group.title[1:]}**", "", *_table(actions), ""]
    subs = subcommands(parser)
    if subs:
        out += ["| Command | Summary |", "|---|---|"]
        for name, sub in subs.items():
            summary = next(c.help for a in parser._actions if isinstance(a, argparse._SubParsersAction)
                           for c in a._choices_actions if c.dest == name)
            out.append(f"| [{name}](#{sub.prog.replace(' ', '-')}) | {_cell(summary or '')} |")
        out.append("")
    if parser.epilog:
        out += ["```text", parser.epilog.strip("\n"), "```", ""]
    for sub in subs.values():
        out += _section(sub, level + 1)
    return out


def markdown(parser: argparse.ArgumentParser | None = None) -> str:
    """The reference page of ``parser`` (default: vibr's) and of its subcommands, as Markdown."""
    parser = build_parser() if parser is None else parser
    head = ["# Command-line reference", "",
            f"Generated from the parsers of the `{parser.prog}` command by `{COMMAND}`: do not edit it by "
            "hand (tests/test_cli_reference.py fails when it is stale). "
            f"`{parser.prog} COMMAND --help` prints the same for one command.", ""]
    return "\n".join(head + _section(parser, 2)).rstrip("\n") + "\n"


def main() -> int:
    sys.stdout.write(markdown())
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
