"""OMRON CompoWay/F: frame codec (codec), typed errors (errors), the serial/socket link with resync, reply
matching, late-reply waits and retries (transport), device URLs (urls), where an amplifier keeps its
measured value (layout), read-rate bookkeeping (rate) and the ZX-L laser amplifier driver (amplifier).

Nothing is imported here: a simulator that imports the codec or the address map (drivers.compowayf.codec,
.layout) loads them alone, without the driver and its serial transport; import from the modules."""
