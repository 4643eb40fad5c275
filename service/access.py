"""Who may do what: the keys file, its roles, and the look-up of a presented key.

The keys file is TOML with one entry per role, each a list of keys:

    viewer = ["a-key-for-the-operator-ui-display-only"]
    operator = ["the-bench-operators-key-0123456789"]
    admin = ["the-line-supervisors-key-abcdefghij"]

Roles are ordered: viewer (read) < operator (sweeps, jobs, emergency stop) < admin (configuration,
schedules); a key of a higher role may do everything a lower one may. A key is at least 16 characters and
belongs to one role only. Any violation is a KeysFileError whose one-line message names the file.

With no keys file the service generates one operator key at start-up and prints it (as Jupyter prints its
token); `KeyRing.generated()` makes it.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path

from estimator.errors import UserError

MIN_KEY_LENGTH = 16
"""Shorter keys are refused: a key is a password, and the service may listen beyond loopback."""


class Role(IntEnum):
    """Roles in increasing order of what they may do."""

    VIEWER = 1
    OPERATOR = 2
    ADMIN = 3

    @property
    def label(self) -> str:
        return self.name.lower()


class KeysFileError(UserError, ValueError):
    """The keys file is unusable; the message is one line and names the file."""


@dataclass(frozen=True)
class Principal:
    """The caller behind a valid key: its role, and a key id (a keyed hash) to record who did what without
    storing the key itself."""

    role: Role
    key_id: str


def key_id(key: str, secret: bytes) -> str:
    """12 hex digits of HMAC-SHA256(secret, key). Viewers see key ids (who submitted a job); an unsalted
    hash of the key would let anyone holding an id test guessed keys offline, a keyed one needs the
    service's secret (KeyRing.fingerprint_secret, kept in the data directory)."""
    return hmac.new(secret, key.encode(), hashlib.sha256).hexdigest()[:12]


class KeyRing:
    """The valid keys and their roles. Look-ups compare in constant time against every key."""

    def __init__(self, keys: Mapping[str, Role], source: str = "keys") -> None:
        self._keys = [(k.encode(), role) for k, role in keys.items()]
        self.source = source
        self.fingerprint_secret = secrets.token_bytes(32)
        """The key of the key ids' HMAC: random per ring; the service replaces it with the one kept in its
        data directory, so that ids stay the same across restarts."""

    def __len__(self) -> int:
        return len(self._keys)

    def lookup(self, presented: str) -> Principal | None:
        candidate = presented.encode()
        found: Role | None = None
        for key, role in self._keys:  # no early exit: the time taken does not depend on which key matched
            if hmac.compare_digest(key, candidate):
                found = role
        return Principal(found, key_id(presented, self.fingerprint_secret)) if found is not None else None

    @classmethod
    def generated(cls) -> tuple[KeyRing, str]:
        """A ring holding one fresh operator key, and that key (for the service to print)."""
        key = secrets.token_urlsafe(24)
        return cls({key: Role.OPERATOR}, source="generated operator key"), key


def load_keys(path: Path | str) -> KeyRing:
    """Read and check a keys file."""
    path = Path(path)
    if not path.is_file():
        raise KeysFileError(f"{path}: no such keys file")
    try:
        document = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise KeysFileError(f"{path}: not valid TOML ({str(exc).splitlines()[0]})") from None
    roles = {r.label: r for r in Role}
    keys: dict[str, Role] = {}
    for name, value in document.items():
        if name not in roles:
            raise KeysFileError(f"{path}: unknown role '{name}' (roles: viewer, operator, admin)")
        if not isinstance(value, list) or not all(isinstance(k, str) for k in value):
            raise KeysFileError(f"{path}: '{name}' must be a list of keys (strings)")
        for key in value:
            if len(key) < MIN_KEY_LENGTH or key != key.strip():
                raise KeysFileError(
                    f"{path}: a key of role '{name}' is shorter than {MIN_KEY_LENGTH} characters "
                    "or has surrounding spaces"
                )
            if key in keys:
                raise KeysFileError(
                    f"{path}: the same key is listed twice (roles '{keys[key].label}', '{name}')"
                )
            keys[key] = roles[name]
    if not keys:
        raise KeysFileError(f'{path}: no keys (expected e.g. operator = ["..."])')
    return KeyRing(keys, source=str(path))
