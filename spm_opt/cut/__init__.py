"""The planned cut on the skull's surface: the contour through the landmarks, and the checks
of a cut on a mesh.
"""
