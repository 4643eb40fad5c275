"""Write a file so that a reader never sees it half-written: a temporary file beside it, then a rename."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO


@contextmanager
def atomic_write(path: Path | str, mode: str = "w", newline: str | None = "") -> Iterator[IO]:
    """Open a temporary file in the target's folder; on success it replaces `path`, on error it vanishes."""
    import tempfile  # here: readers import this module too, and tempfile costs a few ms to import

    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent or Path("."))
    try:
        with os.fdopen(fd, mode, **({"newline": newline} if "b" not in mode else {})) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_atomically(path: Path | str, writer: Callable[[IO], None], mode: str = "w") -> None:
    with atomic_write(path, mode) as handle:
        writer(handle)
