"""The installed package's version (light to import: the command line's ``--version``)."""

from __future__ import annotations

from importlib import metadata


def package_version() -> str:
    """The version of the installed ``spm_opt`` distribution, or "unknown"."""
    try:
        return metadata.version("spm_opt")
    except metadata.PackageNotFoundError:
        return "unknown"
