"""The Control Kernel: scheduler, sensor/control/actuation services, monitoring, node builder (§3.1)."""
