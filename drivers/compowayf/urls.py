"""Device URLs for CompoWay/F amplifiers: where the port is, which node, which serial settings.

    serial:///dev/ttyUSB0?baudrate=38400&parity=E&node=1    a serial device (RS-232C via ZX-SF11, RS-485)
    /dev/pts/7?node=1                                        a plain device path works too
    socket://127.0.0.1:9000?node=2                           a serial-to-Ethernet converter or simulator

Everything goes through pyserial's serial_for_url in the end; the query keys this module understands
(node, baudrate, bytesize, parity, stopbits, timeout_s, retries, late_reply_s, echo) are taken out of the URL
first because
pyserial's URL handlers reject options they do not know. Other query options (e.g. socket's logging=debug)
are passed on to pyserial untouched. "serial://" + path is not a pyserial scheme: it means the plain path.

Link options (drivers.compowayf.transport.LinkSettings): timeout_s= the reply timeout (default 0.5 s; OMRON
documents replies up to 3 s), late_reply_s= how long after an unanswered request to drain the line before the
next one (default 3 s, OMRON's worst case), retries=, echo=1 for an adapter that echoes the host's frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from urllib.parse import parse_qsl, urlencode, urlsplit

from drivers.compowayf.errors import DeviceUrlError

_PARITIES = {
    "N": "N",
    "NONE": "N",
    "E": "E",
    "EVEN": "E",
    "O": "O",
    "ODD": "O",
    "M": "M",
    "MARK": "M",
    "S": "S",
    "SPACE": "S",
}


@dataclass(frozen=True)
class SerialSettings:
    """Line settings passed to serial_for_url. The defaults (38400 bit/s, 8 data bits, no parity, 1 stop
    bit) are an assumption for the ZX-SF11; set them to whatever the amplifier's communication menu says.
    Over socket:// they are ignored by pyserial (the converter's own settings apply)."""

    baudrate: int = 38400
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1

    def __post_init__(self) -> None:
        if self.baudrate <= 0:
            raise DeviceUrlError(f"baudrate must be positive, got {self.baudrate}")
        if self.bytesize not in (5, 6, 7, 8):
            raise DeviceUrlError(f"bytesize must be 5..8, got {self.bytesize}")
        if self.parity not in _PARITIES.values():
            raise DeviceUrlError(f"parity must be one of N E O M S, got {self.parity!r}")
        if self.stopbits not in (1, 1.5, 2):
            raise DeviceUrlError(f"stopbits must be 1, 1.5 or 2, got {self.stopbits}")

    def as_kwargs(self) -> dict[str, float | int | str]:
        return {
            "baudrate": self.baudrate,
            "bytesize": self.bytesize,
            "parity": self.parity,
            "stopbits": self.stopbits,
        }


@dataclass(frozen=True)
class DeviceUrl:
    """A parsed device URL: what to hand serial_for_url, and the settings taken out of the query."""

    pyserial_url: str
    node: int | None = None
    serial: SerialSettings = field(default_factory=SerialSettings)
    timeout_s: float | None = None
    retries: int | None = None
    late_reply_s: float | None = None
    echo: bool = False


_BOOLEANS = {word: True for word in ("1", "true", "yes", "on")} | {
    word: False for word in ("0", "false", "no", "off")
}


def _number(key: str, text: str, kind: type[int] | type[float]) -> float:
    try:
        return kind(text)
    except ValueError:
        raise DeviceUrlError(f"URL option {key}={text!r} is not a number") from None


def parse_device_url(url: str, serial_defaults: SerialSettings | None = None) -> DeviceUrl:
    """Split a device URL into the pyserial URL and our settings; raises DeviceUrlError on bad options."""
    serial = serial_defaults or SerialSettings()
    if "://" in url:
        parts = urlsplit(url)
        location = parts.netloc + parts.path if parts.scheme.lower() == "serial" else None
        query = parts.query
    else:
        location, _, query = url.partition("?")
    node: int | None = None
    timeout_s: float | None = None
    retries: int | None = None
    late_reply_s: float | None = None
    echo = False
    passed_on: list[tuple[str, str]] = []
    for key, value in parse_qsl(query, keep_blank_values=True):
        if key == "node":
            node = int(_number(key, value, int))
            if not 0 <= node <= 99:
                raise DeviceUrlError(f"node must be 0..99, got {node}")
        elif key in ("baudrate", "bytesize"):
            serial = replace(serial, **{key: int(_number(key, value, int))})
        elif key == "stopbits":
            serial = replace(serial, stopbits=_number(key, value, float))
        elif key == "parity":
            if value.upper() not in _PARITIES:
                raise DeviceUrlError(f"parity must be N, E, O, M or S, got {value!r}")
            serial = replace(serial, parity=_PARITIES[value.upper()])
        elif key == "timeout_s":
            timeout_s = _number(key, value, float)
            if timeout_s <= 0:
                raise DeviceUrlError(f"timeout_s must be positive, got {value}")
        elif key == "late_reply_s":
            late_reply_s = _number(key, value, float)
            if late_reply_s < 0:
                raise DeviceUrlError(f"late_reply_s must be >= 0, got {value}")
        elif key == "echo":
            if value.lower() not in _BOOLEANS:
                raise DeviceUrlError(f"echo must be 1 or 0 (true/false), got {value!r}")
            echo = _BOOLEANS[value.lower()]
        elif key == "retries":
            retries = int(_number(key, value, int))
            if retries < 0:
                raise DeviceUrlError(f"retries must be >= 0, got {value}")
        else:
            passed_on.append((key, value))
    if location is not None:  # a device path: pyserial takes no query options for it
        if passed_on:
            unknown = ", ".join(key for key, _ in passed_on)
            raise DeviceUrlError(f"unknown option(s) for a serial device: {unknown}")
        if not location:
            raise DeviceUrlError(f"no device path in {url!r}")
        pyserial_url = location
    else:
        base = url.split("?", 1)[0]
        pyserial_url = base + ("?" + urlencode(passed_on) if passed_on else "")
    return DeviceUrl(pyserial_url, node, serial, timeout_s, retries, late_reply_s, echo)
