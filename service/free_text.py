"""Free text from clients (an operator's name): which characters it may not hold, and how stored text is
shown on a terminal.

A name is printed by `shockbench history` and shown in the web page. Control characters in it would reach
the terminal raw: ESC starts escape sequences (colours, cursor moves, window titles, on some terminals
worse), CR and BS overwrite what is already printed. Bidirectional overrides and isolates reorder what is
displayed without changing what is stored (the "trojan source" trick), so a line can read differently
from what it holds. So the API (service.api.schemas.FreeText) and `shockbench sweep --operator` refuse:

- every control character (Unicode category Cc: C0 U+0000-U+001F including tab and newline, DEL U+007F,
  C1 U+0080-U+009F): a name is one line;
- the bidirectional marks, embeddings, overrides and isolates (U+061C, U+200E, U+200F, U+202A-U+202E,
  U+2066-U+2069);
- the line and paragraph separators U+2028 and U+2029.

Other format characters (the zero-width joiner of emoji and Indic scripts, the soft hyphen) stay allowed.
Text stored before this check (an old database) is printed through `escaped`.

Pure Python, no imports beyond the standard library: every CLI command may import it.
"""

from __future__ import annotations

import unicodedata

BIDI_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")
"""Arabic letter mark, LRM, RLM, the embeddings and overrides LRE RLE PDF LRO RLO, the isolates LRI RLI
FSI PDI."""
SEPARATORS = frozenset("\u2028\u2029")


def is_forbidden(character: str) -> bool:
    """A control character, a bidirectional control or a line/paragraph separator (module docstring)."""
    return character in BIDI_CONTROLS or character in SEPARATORS or unicodedata.category(character) == "Cc"


def first_forbidden(text: str) -> tuple[int, str] | None:
    """(position, character) of the first forbidden character in `text`; None when there is none."""
    for position, character in enumerate(text):
        if is_forbidden(character):
            return position, character
    return None


def code_point(character: str) -> str:
    """U+001B."""
    return f"U+{ord(character):04X}"


def problem(text: str) -> str | None:
    """What is wrong with `text` as free text, in words (naming the first forbidden character and its
    position, never the character itself); None when it may be stored."""
    found = first_forbidden(text)
    if found is None:
        return None
    position, character = found
    name = unicodedata.name(character, "a control character")
    return (
        f"must not contain control characters or bidirectional overrides; {code_point(character)} "
        f"({name.lower()}) at position {position}"
    )


def escaped(text: str) -> str:
    """`text` for a terminal: each forbidden character written as its Python escape (ESC as \\x1b, a
    newline as \\n, RLO as \\u202e), everything else as it is."""
    if first_forbidden(text) is None:
        return text
    return "".join(
        character.encode("unicode_escape").decode("ascii") if is_forbidden(character) else character
        for character in text
    )


JSON_WHITESPACE = frozenset("\t\n\r")
"""Whitespace between a JSON document's tokens (an indented document's line breaks); inside its strings
an encoder always escapes them."""


def json_escaped(json_text: str) -> str:
    """JSON text for a terminal: each other forbidden character a \\uXXXX escape (such characters can only
    stand inside JSON strings, where that escape means the same character: the document is unchanged).
    JSON encoders escape C0 already, not DEL, C1 nor the bidirectional controls."""
    return "".join(
        f"\\u{ord(c):04x}" if c not in JSON_WHITESPACE and is_forbidden(c) else c for c in json_text
    )
