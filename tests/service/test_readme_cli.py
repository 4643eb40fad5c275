"""The README's command line says what `--help` says: its synopsis ("## Command line") shows every
command, and for each the options `shockbench COMMAND --help` lists, no more and no fewer; any other
`shockbench` command line in the README (examples in code blocks and in the text) uses only options that
exist. A spelling kept only for old scripts (service/cli/options.py) is hidden from --help, so the README
cannot show it either.

Generic on purpose: a command or an option added to the CLI fails here until the synopsis shows it, and the
synopsis is the one place to update."""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_help import LONG_OPTION, help_text, usage_options

from service.cli.main import build_parser

README = Path(__file__).resolve().parents[2] / "README.md"
SYNOPSIS_HEADING = "## Command line"
COMMAND_START = re.compile(r"^(?P<indent> {4,})(?:\S*/)?shockbench(?: |$)")
INLINE_COMMAND = re.compile(r"`((?:[^`\s]*/)?shockbench [^`]+)`")


@dataclass(frozen=True)
class CommandLine:
    """One `shockbench ...` command line of the README: the command's words (`("db", "upgrade")`; `()` for
    the program itself) and the long options it shows."""

    words: tuple[str, ...]
    options: frozenset[str]
    text: str


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


PROGRAM = build_parser()


def command_words(tokens: list[str]) -> tuple[str, ...]:
    """The leading tokens that name a command and its subcommands (`db upgrade`), by the parser itself."""
    words: list[str] = []
    parser = PROGRAM
    for token in tokens:
        choices = _subcommands(parser)
        if token not in choices:
            break
        words.append(token)
        parser = choices[token]
    return tuple(words)


def every_command(
    parser: argparse.ArgumentParser = PROGRAM, words: tuple[str, ...] = ()
) -> set[tuple[str, ...]]:
    """Every command a user can run: the program (`--version`) and each leaf of the subcommand tree."""
    found = {words} if words == () else set()
    for name, sub in _subcommands(parser).items():
        found |= every_command(sub, (*words, name)) if _subcommands(sub) else {(*words, name)}
    return found


def parse(text: str) -> CommandLine:
    """A command line: comments cut, words named by the parser, long options but --help."""
    text = " ".join(re.sub(r"\s#.*$", "", line) for line in text.splitlines()).strip()
    tokens = text.split()
    assert re.fullmatch(r"(\S*/)?shockbench", tokens[0]), text
    words = command_words(tokens[1:])
    options = frozenset(LONG_OPTION.findall(text)) - {"--help"}
    return CommandLine(words, options, text)


def code_block_command_lines(markdown: str) -> list[CommandLine]:
    """The `shockbench ...` lines of indented code blocks, each with the lines indented deeper under it."""
    found: list[str] = []
    indent = None
    for line in markdown.splitlines():
        start = COMMAND_START.match(line)
        if start:
            found.append(line)
            indent = len(start.group("indent"))
        elif indent is not None and line.strip() and len(line) - len(line.lstrip(" ")) > indent:
            found[-1] += "\n" + line
        else:
            indent = None
    return [parse(text) for text in found]


def readme_sections() -> tuple[str, str]:
    """(the synopsis section, the rest of the README)."""
    text = README.read_text(encoding="utf-8")
    start = text.index(f"\n{SYNOPSIS_HEADING}\n")
    end = text.index("\n## ", start + 1)
    return text[start:end], text[:start] + text[end:]


def synopsis() -> dict[tuple[str, ...], set[str]]:
    """Each command the synopsis shows and the options it shows for it (over all its lines)."""
    shown: dict[tuple[str, ...], set[str]] = {}
    for line in code_block_command_lines(readme_sections()[0]):
        shown.setdefault(line.words, set()).update(line.options)
    return shown


SYNOPSIS = synopsis()


def test_the_synopsis_shows_every_command() -> None:
    missing = every_command() - set(SYNOPSIS)
    assert not missing, f"commands missing from the README's synopsis: {sorted(' '.join(w) for w in missing)}"
    assert set(SYNOPSIS) <= every_command()  # and nothing that is not a command


@pytest.mark.parametrize("words", sorted(SYNOPSIS), ids=lambda words: " ".join(words) or "shockbench")
def test_the_synopsis_shows_exactly_the_options_of_help(words: tuple[str, ...]) -> None:
    in_help = usage_options(*words)
    in_readme = SYNOPSIS[words]
    command = " ".join(("shockbench", *words))
    assert not in_readme - in_help, (
        f"{command}: the README shows options --help does not: {in_readme - in_help}"
    )
    assert not in_help - in_readme, (
        f"{command}: --help has options the README does not show: {in_help - in_readme}"
    )


def test_every_other_command_line_of_the_readme_uses_real_options() -> None:
    rest = readme_sections()[1]
    lines = code_block_command_lines(rest) + [parse(text) for text in INLINE_COMMAND.findall(rest)]
    checked = [line for line in lines if line.words]
    assert len(checked) >= 10  # the README's examples were found at all
    for line in checked:
        unknown = line.options - usage_options(*line.words)
        assert not unknown, f"README: `{line.text}` uses options --help does not have: {sorted(unknown)}"


def test_a_hidden_old_spelling_does_not_count_as_an_option() -> None:
    assert "--duration-s" in usage_options("simulate")
    assert "--seconds" not in usage_options("simulate")


def test_diagnose_help_states_the_doctors_default_points() -> None:
    from estimator.doctor.diagnose import DEFAULT_POINTS
    from service.cli.diagnose import DOCTOR_POINTS

    assert DOCTOR_POINTS == DEFAULT_POINTS
    text = " ".join(help_text("diagnose").split())
    assert f"default {DEFAULT_POINTS['quarter-car']}, axle {DEFAULT_POINTS['axle']} per side" in text
    readme = " ".join(README.read_text(encoding="utf-8").split())
    assert f"the curve has {DEFAULT_POINTS['quarter-car']} points by default" in readme
