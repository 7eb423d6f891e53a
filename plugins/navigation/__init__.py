"""The Turtlebot's mobile services (thesis §7.1, Table 7.1): LaserSensor.Scan (``plugin.laser-scan``),
MobileBase.Displacement (``plugin.base-displacement``) and Navigation.AMCL (``plugin.amcl-navigation``)."""
