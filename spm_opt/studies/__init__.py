"""Studies built on the rest: the planner comparison, the paper reproduced, its hardware
verification, and parameter sweeps.
"""
