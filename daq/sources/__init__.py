"""Sources: the drivers feeding the acquisition, each into a ring buffer of its own at its own rate."""
