"""Write a sweep of the independent world in the project's interchange formats (README, "Interchange
formats"): the recording CSV ('# key: value' metadata, header t and the channels, one row per sample) and the
vehicle TOML ([vehicle] table). Written here from the format's description, not with the project's writer,
so the world shares only the format with the project. Each file is written to a temporary name beside it
and renamed, so a reader never sees half a file."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from simulators.independent.world import WorldRecording


def _replace_atomically(path: Path, text: str) -> None:
    temporary = path.with_name(f".{path.name}.partial")
    temporary.write_text(text)
    os.replace(temporary, path)


def recording_csv_text(recording: WorldRecording) -> str:
    names = list(recording.measured)
    lines = [f"# {key}: {value}" for key, value in recording.metadata.items()]
    lines.append(",".join(["t", *names]))
    columns = np.column_stack([recording.time_s, *[recording.measured[n] for n in names]])
    for row in columns:
        # readings are whole micrometres: nine significant digits keep them exactly
        lines.append(",".join([f"{row[0]:.6f}", *(f"{v:.9e}" for v in row[1:])]))
    return "\n".join(lines) + "\n"


def vehicle_toml_text(stated: Mapping[str, float | str | bool]) -> str:
    lines = ["[vehicle]"]
    for key, value in stated.items():
        if isinstance(value, bool):
            lines.append(f"{key} = {'true' if value else 'false'}")
        elif isinstance(value, str):
            lines.append(f'{key} = "{value}"')
        else:
            lines.append(f"{key} = {float(value)!r}")
    return "\n".join(lines) + "\n"


def write_recording(recording: WorldRecording, csv_path: Path | str, toml_path: Path | str) -> None:
    """The recording CSV and the vehicle TOML of one sweep."""
    _replace_atomically(Path(csv_path), recording_csv_text(recording))
    _replace_atomically(Path(toml_path), vehicle_toml_text(recording.stated))
