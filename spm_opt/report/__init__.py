"""Reporting: column headings and units once, markdown tables, and figures that take data.

Nothing here imports the modules that compute what it shows (comparison, sweeps,
reproduction, hardware verification): they call in, never the other way.
"""
