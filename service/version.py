"""Depict's version (the installed package's), cheap to import: ``depict --version``."""

from __future__ import annotations

from functools import cache


@cache
def version() -> str:
    """The installed ``depict`` distribution's version, or ``0+unknown`` from a bare checkout."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("depict")
    except PackageNotFoundError:
        return "0+unknown"
