"""The environment at run time (thesis §6.1): map model, semantic dictionary, zoom map, path planning, sharing."""
