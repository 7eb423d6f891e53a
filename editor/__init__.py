"""The PySide6 configuration editor (issue F)."""
