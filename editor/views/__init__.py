"""The editor's views: system tree, attribute form, problems, mission canvas, topic graph, plan."""
