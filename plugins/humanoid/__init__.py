"""The humanoid's services (thesis §7.1, Table 7.2): the NaoQi bridge and the pan-tilt camera's tracking."""
