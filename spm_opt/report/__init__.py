"""Reporting: column headings and units once, figures that take data, the review page.

Nothing here imports the modules that compute what it shows (comparison, sweeps,
reproduction, hardware verification): they call in, never the other way. The executed
cut's judgement it shows comes from :mod:`spm_opt.verify`.
"""
