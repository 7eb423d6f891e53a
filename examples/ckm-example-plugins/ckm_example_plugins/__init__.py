"""Example CKM plugins, one per extension point (see docs/writing-plugins.md in the CKM repository)."""
