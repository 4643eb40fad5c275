"""`shockbench export`: write the recording CSV of a recording, an HDF5 sweep (daq/storage/hdf5_recording)
or a recording CSV, told apart by content (daq.formats.recording_file)."""

from __future__ import annotations

import argparse


def run_export(args: argparse.Namespace) -> int:
    from daq.formats.recording_file import export_recording_csv

    recording = export_recording_csv(args.path, args.out, allow_gaps=args.allow_gaps)
    n = recording.time_s.size
    print(
        f"wrote {args.out}: {n} samples at {recording.sample_time_s * 1e3:g} ms "
        f"({', '.join(recording.channels)})"
    )
    if "gap_free_stretch" in recording.metadata:
        print(f"note: gaps left out, exported {recording.metadata['gap_free_stretch']}")
    if recording.metadata.get("status", "complete") != "complete":  # a CSV may not say (a simulation's)
        print(f"note: the recording is incomplete ({recording.metadata.get('reason') or 'no reason given'})")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="export an HDF5 recording to the recording CSV",
        description="Write the recording CSV (t and displacements in m, metadata as '# key: value' lines) "
        "of an HDF5 recording (or rewrite a recording CSV as read; the content tells which, not the name). "
        "A recording with gaps is refused unless --allow-gaps is given.",
    )
    p.add_argument("path", help="HDF5 recording (shockbench sweep), or a recording CSV")
    p.add_argument("--out", required=True, help="recording CSV to write")
    p.add_argument(
        "--allow-gaps",
        action="store_true",
        help="if the recording has gaps, export its longest gap-free stretch (said in the CSV metadata)",
    )
    p.set_defaults(handler=run_export)
