"""Processing plugins of the Smart Plugin Topology (§3.2.2): image, depth, recognition and fusion (§6.3, §7.4.1)."""
