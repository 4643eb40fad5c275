"""`shockbench sim-devices` and `shockbench probe` (being written)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:  # placeholder until the devices commands land
    del sub
