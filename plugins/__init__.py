"""Processing plugins, controllers and hardware backends registered under ``ckm.plugins``."""
