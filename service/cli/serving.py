"""``depict serve``: the HTTP service (:mod:`service.http`), settings from ``DEPICT_*``
variables and the command line."""

from __future__ import annotations

import argparse

from service.cli.args import UsageError
from service.http.server import serve
from service.settings import Settings


def cmd_serve(args: argparse.Namespace) -> int:
    overrides = {"host": args.host, "port": args.port, "workers": args.workers}
    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValueError as exc:
        raise UsageError(str(exc).replace("\n", " ")) from None
    serve(settings)
    return 0
