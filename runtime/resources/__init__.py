"""Smart Resources (thesis ch. 3.2 and 4): the plugin topology, buffers, quality policies and the TCM.

Import the modules themselves (``runtime.resources.quality``, ``runtime.resources.tcm``, ...):
the package imports nothing, so using one part does not load the others (scikit-learn included).
"""
