"""When a silent laser ends a sweep: the silence limit per source, reconciled with OMRON's wait after a lost
reply.

A source that delivers no new sample for `silence_timeout_s` (the sweep's setting, 0.5 s by default) is
taken for dead and the sweep stops. One lost reply must not look like that: after a request goes
unanswered, OMRON's rule keeps the whole line quiet until a late reply can no longer come
(`LinkSettings.late_reply_s`, 3 s; drivers/compowayf/transport.py), so every laser on that line is silent
for about that long even though nothing is broken. So, per source:

    limit = silence_timeout_s                                           the line lost no reply
    limit = silence_timeout_s + max(late_reply_s, timeout_s) + timeout_s   it did, since the source's
                                                                        last sample (or waits for one)

The extension is the line's documented wait, counted from the lost request (at least its own reply
timeout), plus the reply timeout of the request after it. One lost reply is answered within it (by the
request sent once the wait is over), and the source delivers again. A line that stays dead (a pulled
cable: every request times out, each starting another wait) is still stopped, `limit` after the source's
last sample: 4.0 s with the default link (0.5 s silence, 3 s wait, 0.5 s timeout). Faults where replies
do come (garbage, bad BCC, an end code, a refusal) start no wait and keep the plain silence limit.
"""

from __future__ import annotations

from collections.abc import Sequence

from daq.sources.laser_source import LaserSource

NO_ERROR = "no error reported"
"""What a silent source's reason says when no read of it failed (its amplifier answers but has nothing)."""


def silence_limit_s(source: LaserSource, silence_timeout_s: float) -> float:
    """The longest `source` may deliver nothing now before the sweep stops (see the module)."""
    if not source.line_lost_reply_since_data():
        return silence_timeout_s
    link = source.amplifier.port.link
    return silence_timeout_s + max(link.late_reply_s, link.timeout_s) + link.timeout_s


def silence_reason(sources: Sequence[LaserSource], silence_timeout_s: float) -> str | None:
    """The one-line reason the sweep stops for the first source silent past its limit, or None."""
    for source in sources:
        silent_s = source.seconds_since_data()
        limit_s = silence_limit_s(source, silence_timeout_s)
        if silent_s > limit_s:
            error = source.statistics().last_error or NO_ERROR
            return (
                f"sensor silence: laser {source.name!r} ({source.channel}) delivered nothing for "
                f"{silent_s:.2f} s, limit {limit_s:.2f} s (last error: {error})"
            )
    return None
