"""Write a file so that a reader never sees it half-written: a temporary file beside it, then a rename.

The file is created with the permissions a plain `open(path, "w")` would give it: 0o666 less the process's
umask (0644 under the usual umask 022), so that a recording, an exported CSV, a result or a report is as
readable as any other file the user writes. tempfile.mkstemp would make every one 0600 whatever the umask.
Only a secret asks for less (`permissions=PRIVATE`, 0600), as the service's key-id secret is made
(service/api/app.py, fingerprint_secret) and the CLI's bug logs (service/cli/errors.py: argv and a traceback
may hold a database URL with its password).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

PUBLIC = 0o666
"""What a new file asks for; the kernel takes the umask away (open(2)), as for any file the user writes."""
PRIVATE = 0o600
"""Readable and writable by the owner alone, whatever the umask: for secrets."""
_CREATE_FLAGS = (
    os.O_WRONLY
    | os.O_CREAT
    | os.O_EXCL
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_CLOEXEC", 0)
    | getattr(os, "O_BINARY", 0)
)
"""A fresh file, never an existing one or a symbolic link planted under its name (as mkstemp opens)."""


def _create_beside(target: Path, permissions: int) -> tuple[int, Path]:
    """A new temporary file in the target's folder, opened for writing; its descriptor and path."""
    folder = target.parent
    while True:
        tmp = folder / f".{target.name}.{os.urandom(6).hex()}.part"
        try:
            return os.open(tmp, _CREATE_FLAGS, permissions), tmp
        except FileExistsError:  # 48 random bits taken already: draw again
            continue


@contextmanager
def atomic_write(
    path: Path | str, mode: str = "w", newline: str | None = "", *, permissions: int = PUBLIC
) -> Iterator[IO]:
    """Open a temporary file in the target's folder; on success it replaces `path`, on error it vanishes.
    `permissions` as for open(2): the umask applies (PUBLIC, the default), or PRIVATE for a secret."""
    target = Path(path)
    fd, tmp = _create_beside(target, permissions)
    try:
        with os.fdopen(fd, mode, **({"newline": newline} if "b" not in mode else {})) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomically(path: Path | str, writer: Callable[[IO], None], mode: str = "w") -> None:
    with atomic_write(path, mode) as handle:
        writer(handle)
