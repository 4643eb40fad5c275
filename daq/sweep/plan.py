"""A sweep checked once, at the edge, against the bench it will run on.

Every way in (`POST /sweeps`, the inspection line's scheduler, `shockbench sweep`) turns its input into a
`SweepRequest` (the plate's settings, the vehicle file as read, who runs it) and calls `plan_sweep` with the
bench's configuration. That is the one place a request is judged before anything moves:

* every channel the bench records has a laser;
* the vehicle file's model is the bench's (a quarter car on a quarter-car bench);
* the sweep lies inside the bench's safety envelope: checked here for a clear message naming the setting,
  and again by the exciter driver as the safety net (drivers/exciter/interface.py), nowhere else;
* the recording can carry the sweep: the grid (1 ms), or a streaming amplifier's slower sampling, gives
  estimator.bandwidth's REFUSE_SAMPLES_PER_PERIOD samples per period of the top frequency. This is the
  rule identify applies to the recording later; a polled amplifier's rate is known only once recorded.

`run_sweep` takes only a `SweepPlan`, so a sweep that ran was planned; the plan carries the parsed vehicle
file down to the recording, so the file is not read again. Errors: `SweepError` (a UserError) with one line
and `field` naming the request's setting to blame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from daq.bench_config import BenchConfig
from daq.sweep.model import SAMPLE_TIME_S, SweepError, SweepRequest
from drivers.exciter.errors import EnvelopeViolationError
from estimator.bandwidth import REFUSE_SAMPLES_PER_PERIOD
from estimator.sweep import SweepSettings


@dataclass(frozen=True)
class SweepPlan:
    """A request that `plan_sweep` found runnable on the bench named `bench`. Make it with plan_sweep."""

    request: SweepRequest
    bench: str

    @property
    def sweep(self) -> SweepSettings:
        return self.request.sweep

    def vehicle_stored_as(self, source: str) -> SweepPlan:
        """The same plan with the vehicle file's name as it was stored (the recording keeps the name);
        the parameters and text, already checked, are unchanged."""
        vehicle = self.request.vehicle
        if vehicle is None:
            return self
        return replace(self, request=replace(self.request, vehicle=replace(vehicle, source=source)))


def plan_sweep(config: BenchConfig, request: SweepRequest, *, vehicle_field: str = "vehicle") -> SweepPlan:
    """Check `request` against the bench `config` describes (see the module); SweepError naming the field
    to blame. `vehicle_field` is what the caller calls the vehicle file (the API's `vehicle_toml`)."""
    missing = [channel for channel in config.channels if config.laser_for(channel) is None]
    if missing:
        raise SweepError(f"bench {config.name!r} has no laser for channel(s) {', '.join(missing)}")
    vehicle = request.vehicle
    if vehicle is not None and vehicle.parameters.model != config.model:
        raise SweepError(
            f"{vehicle.source}: a {vehicle.parameters.model} vehicle cannot be tested on the "
            f"{config.model} bench {config.name!r}",
            field=vehicle_field,
        )
    try:
        config.safety_envelope().check(request.sweep)
    except EnvelopeViolationError as exc:
        raise SweepError(str(exc), field=exc.field) from None
    check_recordable(config, request.sweep)
    return SweepPlan(request, config.name)


def check_recordable(config: BenchConfig, settings: SweepSettings) -> None:
    """SweepError (field stop_Hz or start_Hz) when the bench's recording could not carry the sweep."""
    periods = [SAMPLE_TIME_S] + [
        laser.sample_period_s for laser in config.lasers if laser.sample_period_s is not None
    ]
    rate_Hz = 1.0 / max(periods)
    top_Hz = max(settings.start_Hz, settings.stop_Hz)
    if top_Hz > 0 and rate_Hz / top_Hz < REFUSE_SAMPLES_PER_PERIOD:
        field = "stop_Hz" if settings.stop_Hz >= settings.start_Hz else "start_Hz"
        raise SweepError(
            f"{field}: the bench records at {rate_Hz:g} Hz, too slow for a sweep up to {top_Hz:g} Hz: "
            f"identification needs {REFUSE_SAMPLES_PER_PERIOD:g} samples per period, so at most "
            f"{rate_Hz / REFUSE_SAMPLES_PER_PERIOD:g} Hz",
            field=field,
        )
