"""Control laws (§3.1.2.2): PID and GPC."""
