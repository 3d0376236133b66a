"""``depict``: the command line. Every command is a thin layer over the service's shared paths
(:mod:`service.enhance`, :mod:`service.scene`, :mod:`service.jobs`, :mod:`service.batch`) and
gbuffer/.

* :mod:`.parser`: the commands and their flags (``depict --help`` imports nothing heavy);
* :mod:`.args`: flags shared by several commands; :mod:`.common`: what their values become
  (the compiled pipeline, the read request);
* one module per group of commands: :mod:`.frames` (enhance, preview, ops), :mod:`.render`
  (render, warmup), :mod:`.inspection`, :mod:`.analysis` (score, compare, relief-pick, arm),
  :mod:`.serving` (serve), :mod:`.sequence` (batch), and :mod:`.remote`: the ``--server`` forms.

Bad input (a bad file, a missing buffer or camera, an unknown operator or parameter) prints one
line ``depict: error: ...`` on stderr and exits with code 2; no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any

from service import allocator
from service.cli.args import drop_stdout, error_line, fail
from service.cli.parser import build_parser
from service.logs import end_process
from service.signals import sigint_held

__all__ = ["build_parser", "main", "run"]


def command(args: argparse.Namespace) -> Callable[[argparse.Namespace], int]:
    """The function of the parsed command: its ``--server`` form when a server is given."""
    target = args.remote if getattr(args, "server", None) and "remote" in args else args.command
    module, _, name = target.partition(":")
    with sigint_held():  # (the threads the imports start keep SIGINT blocked: service.signals)
        found: Callable[[argparse.Namespace], int] = getattr(importlib.import_module(module), name)
    return found


class _Stopped(BaseException):
    """SIGTERM or SIGHUP, raised where the command is, so that it ends as Ctrl-C does: a file
    being written is removed on the way out (:func:`gbuffer.atomic.atomic_path`), never left
    half-written beside its output."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _stop(signum: int, _frame: object) -> None:
    for each in _stops():  # once: a second signal must not interrupt the cleanup
        if signal.getsignal(each) is _stop:  # (main() puts back what it replaced)
            signal.signal(each, signal.SIG_IGN)
    raise _Stopped(signum)


def _stops() -> list[int]:
    return [s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)) if s]


def _catch_stops(args: argparse.Namespace, replaced: dict[int, Any]) -> None:
    """Install :func:`_stop` for SIGTERM and SIGHUP where they have their default action (not
    where they are ignored, as ``nohup`` leaves SIGHUP; not for ``serve``, whose server
    handles them; not off the main thread); the handlers it replaced go into ``replaced``."""
    serving = args.command.startswith("service.cli.serving:")
    if serving or threading.current_thread() is not threading.main_thread():
        return
    for each in _stops():
        if signal.getsignal(each) is signal.SIG_DFL:
            replaced[each] = signal.SIG_DFL  # (first: a signal as it is installed is restored)
            signal.signal(each, _stop)


def _standard_streams() -> None:
    """Open /dev/null on descriptors 0, 1 and 2 where they are closed (``depict ... >&-``), and
    give Python the streams it then lacks: otherwise the first files the command opens get those
    numbers, and what is printed (or what the reader points at a temporary file while the
    OpenEXR library decodes: :mod:`gbuffer.capture`) would land in an output being written."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            opened = os.open(os.devnull, os.O_RDWR)  # (the lowest free number: this one)
            if opened != fd:
                os.dup2(opened, fd)
                os.close(opened)
    for name, fd in (("stdout", 1), ("stderr", 2)):
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", closefd=False))


def main(argv: Sequence[str] | None = None) -> int:
    _standard_streams()
    allocator.tune()
    args = build_parser().parse_args(argv)
    replaced: dict[int, Any] = {}
    try:
        _catch_stops(args, replaced)
        return int(command(args)(args))
    except KeyboardInterrupt:
        return 130
    except _Stopped as stop:
        return 128 + stop.signum
    except BrokenPipeError:  # (``depict ops | head``: the reader has all it wanted)
        drop_stdout()
        return 128 + signal.SIGPIPE
    except Exception as exc:  # bad input, a server that refused or is down: one line
        line = error_line(exc)
        if line is None:
            raise
        return fail(line)
    finally:
        for signum, handler in replaced.items():
            signal.signal(signum, handler)


def run() -> None:
    """The ``depict`` executable: :func:`main`, then the process ends without tearing the
    interpreter down (:func:`service.logs.end_process`: 0.16–0.3 s of a 2.3 s ``depict enhance``
    at 1080p). ``--help``, ``--version`` and usage errors exit as usual."""
    end_process(main())
