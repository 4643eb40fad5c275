"""The recording CSV: the interchange format between acquisition, simulation and identification.

Optional lines starting with '#' (metadata as '# key: value'), then a header row, then one row per sample.
Column t in seconds; displacements in metres, upward positive, measured from the static position.
Quarter car: t,x_s,x_t,x_r. Axle: t,x_s_l,x_s_r,x_t_l,x_t_r,x_r_l,x_r_r. The sample time must be uniform
(1 ms at the bench). The file is UTF-8 text. Any violation (bytes that are not UTF-8 included) is a
RecordingFormatError whose one-line message names the file and the line.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from daq.formats.atomic import atomic_write
from estimator.errors import InvalidValueError, UserError, one_line
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS, Recording

UNIFORM_TOLERANCE = 1e-3
"""A sample interval may differ from the first one by this fraction (timestamps printed to 1 µs)."""


class RecordingFormatError(UserError, ValueError):
    """The file is not a valid recording CSV; the message names the line."""


@dataclass
class _Layout:
    """A recording CSV's lines sorted out: metadata ('# key: value' before the header), the header's cells
    and line, and the data rows with their 1-based line numbers (blank and '#' lines skipped)."""

    metadata: dict[str, str] = field(default_factory=dict)
    header: list[str] | None = None
    header_line: int = 0
    rows: list[tuple[int, str]] = field(default_factory=list)


def _layout(lines: Iterable[str], path: Path) -> _Layout:
    """One pass over the lines, shared by both readers below."""
    layout = _Layout()
    for line_no, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if layout.header is None and ":" in line:
                key, _, value = line[1:].partition(":")
                layout.metadata[key.strip()] = value.strip()
            continue
        if layout.header is None:
            layout.header = [c.strip() for c in _cells(path, line_no, line)]
            layout.header_line = line_no
            continue
        layout.rows.append((line_no, line))
    return layout


def _cells(path: Path, line_no: int, line: str) -> list[str]:
    """The CSV cells of one line (a cell over the csv module's size limit: RecordingFormatError)."""
    try:
        return next(csv.reader([line]))
    except csv.Error as exc:
        raise RecordingFormatError(f"{path}:{line_no}: not a CSV line ({one_line(exc)})") from None


def _text(path: Path) -> str:
    """The file's text (RecordingFormatError naming the line of the first byte that is not UTF-8)."""
    data = path.read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line_no = data.count(b"\n", 0, exc.start) + 1
        raise RecordingFormatError(
            f"{path}:{line_no}: not a text file (UTF-8 expected; byte 0x{data[exc.start]:02x} is not UTF-8)"
        ) from None


def _recording(
    path: Path, t: np.ndarray, channels: dict[str, np.ndarray], metadata: dict[str, str]
) -> Recording:
    """The Recording, its own checks' error naming the file."""
    try:
        return Recording(t, channels, metadata)
    except InvalidValueError as exc:
        raise RecordingFormatError(f"{path}: {one_line(exc)}") from None


def read_recording_csv(path: Path | str) -> Recording:
    path = Path(path)
    if not path.is_file():
        raise RecordingFormatError(f"{path}: no such file")
    text = _text(path)
    fast = _read_well_formed(path, text)
    if fast is not None:
        return fast
    layout = _layout(io.StringIO(text, newline=""), path)  # lines as an editor numbers them
    header = layout.header
    if header is None:
        raise RecordingFormatError(f"{path}: no header row (expected t,x_s,x_t,x_r or the axle columns)")
    _check_header(path, header, layout.header_line)
    rows: list[list[float]] = []
    for line_no, line in layout.rows:
        cells = _cells(path, line_no, line)
        if len(cells) != len(header):
            raise RecordingFormatError(f"{path}:{line_no}: expected {len(header)} values, found {len(cells)}")
        try:
            values = [float(c) for c in cells]
        except ValueError:
            raise RecordingFormatError(f"{path}:{line_no}: not a number in {line!r}") from None
        bad = [header[i] for i, v in enumerate(values) if not math.isfinite(v)]
        if bad:
            raise RecordingFormatError(f"{path}:{line_no}: missing or non-finite value in column {bad[0]}")
        rows.append(values)
    if len(rows) < 3:
        raise RecordingFormatError(f"{path}: only {len(rows)} data rows; a recording needs at least 3")
    data = np.array(rows)
    t = data[:, header.index("t")]
    _check_uniform(path, t, first_data_line=layout.rows[0][0])
    channels = {name: data[:, i] for i, name in enumerate(header) if name != "t"}
    return _recording(path, t, channels, layout.metadata)


def _read_well_formed(path: Path, text: str) -> Recording | None:
    """The recording, parsed by numpy's C reader, when the file is well formed; None otherwise, and the
    line-by-line reader above then finds and names the first bad line. Why: that reader spends some 0.1 s
    per 10 000 rows in Python, a tenth of a whole `shockbench identify`."""
    try:
        layout = _layout(text.splitlines(), path)
    except RecordingFormatError:
        return None
    header = layout.header
    if header is None or len(layout.rows) < 3:
        return None
    data_lines = [line for _, line in layout.rows]
    try:
        _check_header(path, header, 0)
        data = np.loadtxt(data_lines, delimiter=",", comments=None, dtype=float, ndmin=2)
    except (RecordingFormatError, ValueError):
        return None
    if data.shape != (len(data_lines), len(header)) or not np.all(np.isfinite(data)):
        return None
    t = data[:, header.index("t")]
    _check_uniform(path, t, first_data_line=layout.rows[0][0])
    channels = {name: np.ascontiguousarray(data[:, i]) for i, name in enumerate(header) if name != "t"}
    return _recording(path, np.ascontiguousarray(t), channels, layout.metadata)


def _check_header(path: Path, header: list[str], line_no: int) -> None:
    names = set(header)
    if len(names) != len(header):
        raise RecordingFormatError(f"{path}:{line_no}: duplicated column in header")
    for channels in (QUARTER_CAR_CHANNELS, AXLE_CHANNELS):
        if names == {"t", *channels}:
            return
    raise RecordingFormatError(
        f"{path}:{line_no}: columns {','.join(header)} are neither t,{','.join(QUARTER_CAR_CHANNELS)} "
        f"nor t,{','.join(AXLE_CHANNELS)}"
    )


def _check_uniform(path: Path, t: np.ndarray, first_data_line: int) -> None:
    with np.errstate(over="ignore"):
        steps = np.diff(t)
    dt = steps[0]
    if not np.all(np.isfinite(steps)):
        raise RecordingFormatError(f"{path}:{first_data_line}: time steps out of range (beyond a float)")
    if not dt > 0:
        raise RecordingFormatError(f"{path}:{first_data_line + 1}: time does not increase")
    off = np.nonzero(np.abs(steps - dt) > UNIFORM_TOLERANCE * dt)[0]
    if off.size:
        i = int(off[0]) + 1
        raise RecordingFormatError(
            f"{path}:{first_data_line + i}: sample time is not uniform (step {steps[i - 1] * 1e3:.6g} ms, "
            f"expected {dt * 1e3:.6g} ms)"
        )


def write_recording_csv(path: Path | str, recording: Recording) -> None:
    """Write atomically (a reader never sees half a file); metadata go to '# key: value' lines."""
    names = AXLE_CHANNELS if recording.is_axle else QUARTER_CAR_CHANNELS
    recording.require(names)
    with atomic_write(path) as handle:
        for key, value in recording.metadata.items():
            handle.write(f"# {key}: {value}\n")
        handle.write(",".join(["t", *names]) + "\n")
        columns = np.column_stack([recording.time_s, *[recording.channels[n] for n in names]])
        np.savetxt(handle, columns, delimiter=",", fmt=["%.6f"] + ["%.9e"] * len(names))
