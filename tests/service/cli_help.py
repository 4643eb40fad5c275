"""What `shockbench ... --help` says, for the tests that compare it with the README and across commands."""

from __future__ import annotations

import contextlib
import io
import re

from service.cli.main import main

LONG_OPTION = re.compile(r"(?<![\w-])--[a-z0-9][a-z0-9-]*")


def help_text(*words: str) -> str:
    """The output of `shockbench WORDS... --help` (argparse exits 0 after printing it)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main([*words, "--help"])
    return out.getvalue()


def usage_options(*words: str) -> set[str]:
    """The long options the usage of `shockbench WORDS... --help` lists (every option but --help, whose
    short form stands there); a hidden old spelling is not among them."""
    usage = help_text(*words).split("\n\n", 1)[0]
    assert usage.startswith("usage: shockbench"), usage
    return set(LONG_OPTION.findall(usage))
