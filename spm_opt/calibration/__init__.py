"""Kinematic calibration from a tracker: encoder zeros and the mechanism's geometry."""
