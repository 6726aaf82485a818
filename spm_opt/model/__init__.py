"""The one model of the robot: parameters, kinematics, actuator."""
