"""Robot models: the description (TOML) → URDF writer, :class:`~.robot.RobotModel` (Pinocchio),
numeric and CasADi kinematics, the free-floating base, inverse kinematics and example robots."""
