"""The bench configuration file: which devices make up a bench, where they are, what each one measures.

One TOML file per bench, read with `load_bench_config` and written with `write_bench_config` (which is what
`shockbench sim-devices` does for the simulated bench it serves). Every key is declared once, with its type,
bounds, unit and help text, in daq.bench_config.models (the devices and the bench) and
daq.bench_config.document (the file's tables); `shockbench config schema` prints the file's JSON Schema
from those declarations and `shockbench config check FILE` checks a file with this reader. examples/ holds
a configuration for every supported combination of devices (docs/configuration.md). A quarter car:

    [bench]
    name = "bench 1"
    model = "quarter-car"                # or "axle"

    [bench.envelope]                     # optional: lowers the sweeps allowed; never above the hard limits
    max_amplitude_m = 0.004              # zero-to-peak plate amplitude
    max_frequency_Hz = 20.0

    [exciter]                            # the plate drive
    name = "plate"
    url = "modbus-tcp://192.168.0.20:502?unit=1"
    register_map = "drive-registers.toml"  # optional (Modbus): relative to this file

    [[lasers]]                           # one table per laser sensor (amplifier + head)
    name = "body"
    url = "serial:///dev/ttyUSB0?baudrate=38400&node=1"
    channel = "x_s"
    head = "ZX-LD100"
    sign = 1                             # optional, default 1
    zero_m = 0.0                         # optional, default 0.0
    sample_period_s = 0.001              # optional: the amplifier samples on its own clock
    buffer_length = 256                  # optional, with sample_period_s

    [[lasers]]
    name = "wheel"
    url = "serial:///dev/ttyUSB0?baudrate=38400&node=2"   # same RS-485 line, next node
    channel = "x_t"
    head = "ZX-LD40"
    value_area = "parameter"             # optional: where the measured value lives
    value_type = 0xC020
    value_address = 0x3000
    value_unit = "nm"

Beyond each key's own checks, a bench checks the whole: device names unique, each channel of its model
measured at most once, no two lasers on one node of one line, the envelope within the hard limits
(drivers.exciter.envelope: by default 4 mm, 25 Hz and 3600 s; a bench allows 4 mm, 25 Hz, 300 s unless it
says less, or a longer duration).

Errors are `BenchConfigError` (a ValueError) with one line naming the file, the line where it is known
(TOML syntax errors and keys are located; a missing key points at its table) and the table and key, e.g.

    bench.toml:14: [[lasers]] #2 channel: channel 'x_s' is already measured by laser 'body'

Must not import service or simulators (daq's layer rule, tests/test_dependency_rules.py).
"""

from daq.bench_config.document import bench_config_schema
from daq.bench_config.errors import BenchConfigError
from daq.bench_config.models import CHANNELS, LASER_HEADS, BenchConfig, ExciterConfig, LaserConfig
from daq.bench_config.toml_io import (
    dump_bench_config,
    load_bench_config,
    parse_bench_config,
    write_bench_config,
)

__all__ = [
    "CHANNELS",
    "LASER_HEADS",
    "BenchConfig",
    "BenchConfigError",
    "ExciterConfig",
    "LaserConfig",
    "bench_config_schema",
    "dump_bench_config",
    "load_bench_config",
    "parse_bench_config",
    "write_bench_config",
]
