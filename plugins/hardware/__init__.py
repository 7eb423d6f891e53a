"""Hardware backends: the loopback plant simulator."""
