"""The arm's services (thesis §7.4.2, Table 7.1 RoboticArm.MoveIt): predefined poses solved by inverse kinematics."""
