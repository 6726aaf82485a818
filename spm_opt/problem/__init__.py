"""The problem and its file, the trajectory type, and the check that a plan or a log was
made for the problem it meets.
"""
