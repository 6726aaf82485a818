"""The robot learned from its own logs: its dynamic parameters and gear efficiency, and its
actuators' position and velocity loops.
"""
