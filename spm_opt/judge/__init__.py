"""The one judge of a plan: the limits (each rule once), the room a feed hold needs, the
duration's lower bound, the report, and the judgement.
"""
