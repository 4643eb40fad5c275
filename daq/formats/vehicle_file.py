"""The vehicle file (TOML): what is known about the wheel(s) under test.

    [vehicle]
    model = "quarter-car"            # or "axle"
    mass_kg = 420.0                  # mass carried by the wheel(s) under test: M_1/4, or M_1/2 for an axle
    # optional: what is not stated is identified from the recording
    spring_stiffness_N_per_m = 26000
    tyre_stiffness_N_per_m = 210000
    tyre_viscoelastic_coefficient = 0.97   # ϑ of the Maxwell tyre (paper eq 5), referred to Δt = 1 ms
    # tyre_relaxation_time_s = 0.0323      # or τ = C_d/K_d instead of ϑ (ϑ = τ/(τ + 1 ms))
    # axle only:
    track_m = 1.5
    anti_roll_bar_stiffness_N_per_m = 18000   # absent = no bar
    # quarter car only: a laboratory rig whose body and wheel ride on guides fixed to a frame
    # frame_guides = true                      # absent = false (a vehicle on a plate)

Only model and mass_kg (and track_m for an axle) are required. An unknown key is an error; a missing
required key is an error that names it. ϑ is referred to 1 ms whatever the recording's sample time
(estimator.vehicle), so a file stays right for a recording from a 500 Hz rig.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from daq.formats.atomic import atomic_write
from estimator.errors import UserError, one_line
from estimator.vehicle import ModelKind, VehicleParameters

REQUIRED = ("model", "mass_kg")
AXLE_REQUIRED = ("track_m",)
OPTIONAL = (
    "spring_stiffness_N_per_m",
    "tyre_stiffness_N_per_m",
    "tyre_viscoelastic_coefficient",
    "tyre_relaxation_time_s",
    "anti_roll_bar_stiffness_N_per_m",
    "frame_guides",
)
FLAGS = ("frame_guides",)
"""Keys that are true or false, not numbers."""


class VehicleFileError(UserError, ValueError):
    """The vehicle file is invalid; the message names the key."""


def parse_vehicle(text: str, source: str = "vehicle file") -> VehicleParameters:
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise VehicleFileError(f"{source}: not valid TOML ({exc})") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise VehicleFileError(f"{source}: not valid TOML ({one_line(exc).partition(':')[0]})") from None
    except RecursionError:  # brackets nested deeper than the parser descends
        raise VehicleFileError(f"{source}: not valid TOML (nested too deeply)") from None
    extra_tables = sorted(set(document) - {"vehicle"})
    if extra_tables:
        raise VehicleFileError(f"{source}: unknown table or key '{extra_tables[0]}' (expected [vehicle])")
    table = document.get("vehicle")
    if not isinstance(table, dict):
        raise VehicleFileError(f"{source}: missing table [vehicle]")
    unknown = sorted(set(table) - set(REQUIRED) - set(AXLE_REQUIRED) - set(OPTIONAL))
    if unknown:
        raise VehicleFileError(f"{source}: unknown key '{unknown[0]}' in [vehicle]")
    for key in REQUIRED:
        if key not in table:
            raise VehicleFileError(f"{source}: missing required key '{key}' in [vehicle]")
    try:
        model = ModelKind(table["model"])
    except ValueError:
        raise VehicleFileError(
            f'{source}: model must be "quarter-car" or "axle", got {table["model"]!r}'
        ) from None
    if model is ModelKind.AXLE:
        for key in AXLE_REQUIRED:
            if key not in table:
                raise VehicleFileError(f"{source}: missing required key '{key}' for an axle")
    elif "track_m" in table or "anti_roll_bar_stiffness_N_per_m" in table:
        key = "track_m" if "track_m" in table else "anti_roll_bar_stiffness_N_per_m"
        raise VehicleFileError(f"{source}: key '{key}' applies to an axle only")
    numbers: dict[str, float] = {}
    flags: dict[str, bool] = {}
    for key, value in table.items():
        if key == "model":
            continue
        if key in FLAGS:
            if not isinstance(value, bool):
                raise VehicleFileError(f"{source}: '{key}' must be true or false, got {value!r}")
            flags[key] = value
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise VehicleFileError(f"{source}: '{key}' must be a number, got {value!r}")
        try:
            numbers[key] = float(value)
        except OverflowError:  # a TOML integer has no size limit
            raise VehicleFileError(f"{source}: '{key}' is too large for a number") from None
    relaxation_time_s = numbers.pop("tyre_relaxation_time_s", None)
    if relaxation_time_s is not None:
        if "tyre_viscoelastic_coefficient" in numbers:
            raise VehicleFileError(
                f"{source}: give tyre_viscoelastic_coefficient or tyre_relaxation_time_s, not both"
            )
        if not relaxation_time_s > 0:
            raise VehicleFileError(f"{source}: tyre_relaxation_time_s must be > 0, got {relaxation_time_s}")
    try:
        vehicle = VehicleParameters(model=model, **numbers, **flags)
        return vehicle.with_relaxation_time(relaxation_time_s) if relaxation_time_s is not None else vehicle
    except ValueError as exc:
        raise VehicleFileError(f"{source}: {exc}") from None


@dataclass(frozen=True)
class VehicleFile:
    """A vehicle file as read once at the edge: its parameters, its text verbatim (a recording keeps it),
    and the name it was read under (quoted in messages, stored with the recording)."""

    parameters: VehicleParameters
    text: str
    source: str


def parse_vehicle_file(text: str, source: str = "vehicle file") -> VehicleFile:
    """The text as a VehicleFile (VehicleFileError naming the key, or "nested too deeply" for a TOML the
    parser cannot descend)."""
    return VehicleFile(parse_vehicle(text, source), text, source)


def load_vehicle_file(path: Path | str) -> VehicleFile:
    """Read and parse the file at `path` (VehicleFileError when missing, not UTF-8 or invalid)."""
    path = Path(path)
    if path.is_dir():
        raise VehicleFileError(f"{path}: is a folder, not a vehicle file")
    if not path.is_file():
        raise VehicleFileError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise VehicleFileError(f"{path}: not a text file (UTF-8 expected)") from None
    return parse_vehicle_file(text, str(path))


def read_vehicle(path: Path | str) -> VehicleParameters:
    """The parameters of the vehicle file at `path` (VehicleFileError naming the problem)."""
    return load_vehicle_file(path).parameters


def format_vehicle(vehicle: VehicleParameters) -> str:
    lines = [
        "[vehicle]",
        f'model = "{vehicle.model.value}"',
        f"mass_kg = {vehicle.mass_kg!r}",
    ]
    for key in ("spring_stiffness_N_per_m", "tyre_stiffness_N_per_m", "tyre_viscoelastic_coefficient"):
        value = getattr(vehicle, key)
        if value is not None:  # not stated: identified from the recording
            lines.append(f"{key} = {value!r}")
    if vehicle.is_axle:
        lines.append(f"track_m = {vehicle.track_m!r}")
        if vehicle.anti_roll_bar_stiffness_N_per_m:
            lines.append(f"anti_roll_bar_stiffness_N_per_m = {vehicle.anti_roll_bar_stiffness_N_per_m!r}")
    if vehicle.frame_guides:
        lines.append("frame_guides = true")
    return "\n".join(lines) + "\n"


def write_vehicle(path: Path | str, vehicle: VehicleParameters) -> None:
    with atomic_write(path) as handle:
        handle.write(format_vehicle(vehicle))
