"""The navigation link: an OpenIGTLink server that shows the robot in 3D Slicer (the tool's
pose, the plan, the run's state) and takes a flap, a registration and commands from it.
Nothing received starts motion."""
