"""A recording as the estimator sees it: uniformly sampled displacement channels in metres."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator.errors import InvalidValueError
from estimator.order_statistics import median

QUARTER_CAR_CHANNELS = ("x_s", "x_t", "x_r")
AXLE_CHANNELS = ("x_s_l", "x_s_r", "x_t_l", "x_t_r", "x_r_l", "x_r_r")


@dataclass
class Recording:
    """Displacements (upward positive, from the static position, metres) sampled every sample_time_s.

    channels maps a channel name (see QUARTER_CAR_CHANNELS, AXLE_CHANNELS) to an array of len(time_s).
    """

    time_s: np.ndarray
    channels: dict[str, np.ndarray]
    metadata: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=float)
        n = self.time_s.size
        if n < 3:
            raise InvalidValueError("a recording needs at least 3 samples")
        for name, values in list(self.channels.items()):
            arr = np.asarray(values, dtype=float)
            if arr.shape != (n,):
                raise InvalidValueError(f"channel {name} has {arr.size} samples, time has {n}")
            if not np.all(np.isfinite(arr)):
                raise InvalidValueError(f"channel {name} has non-finite values")
            self.channels[name] = arr
        steps = np.diff(self.time_s)
        dt = float(median(steps))
        if dt <= 0 or np.max(np.abs(steps - dt)) > 1e-3 * dt:
            bad = int(np.argmax(np.abs(steps - dt))) + 1
            raise InvalidValueError(
                f"sample time is not uniform at sample {bad} (t = {self.time_s[bad]:.6f} s)"
            )

    @property
    def sample_time_s(self) -> float:
        return float((self.time_s[-1] - self.time_s[0]) / (self.time_s.size - 1))

    @property
    def is_axle(self) -> bool:
        return all(c in self.channels for c in AXLE_CHANNELS)

    def require(self, names: tuple[str, ...]) -> None:
        missing = [c for c in names if c not in self.channels]
        if missing:
            raise InvalidValueError(f"recording lacks channel(s) {', '.join(missing)}")
