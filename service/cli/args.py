"""Flags and argument helpers shared by the commands of ``depict`` (:mod:`service.cli`): the
standard library only, so that building the parser (``depict --help``) imports nothing heavy."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import sys
from collections.abc import Callable
from typing import Any


class UsageError(ValueError):
    """A command line that cannot be honoured (bad flag value, missing file, ...)."""


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


#: The exit code of bad input (and of argparse's usage errors).
EXIT_USAGE = 2


def fail(message: str) -> int:
    """One line on stderr, control characters escaped; the exit code of bad input."""
    note(f"depict: error: {printable(message)}")
    return EXIT_USAGE


def say(line: str) -> None:
    """``line`` on standard output, flushed. Where that output is gone (a reader that closed its
    pipe: ``depict enhance *.exr -o out | head -1``; a full disk) its lines stop and the command
    goes on: that is no file's failure. A reason other than a closed pipe is said once on
    stderr."""
    try:
        print(line, flush=True)
    except OSError as exc:
        drop_stdout()
        if not isinstance(exc, BrokenPipeError):
            note(f"depict: warning: standard output: {exc.strerror or exc}; its lines are dropped")


def note(line: str) -> None:
    """``line`` on stderr, if it can still be written (a reader gone from ``2>&1 | head -1`` is
    no reason to stop enhancing the other files)."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr, flush=True)


def drop_stdout() -> None:
    """Point standard output at /dev/null: what is still buffered for a closed pipe (or a full
    disk) is let go instead of failing again as the process ends."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def error_line(exc: BaseException) -> str | None:
    """What ``depict: error:`` says of a failure caused by the input, the files or the server
    (``None``: a bug, which keeps its traceback)."""
    from service.errors import DepictError

    if isinstance(exc, ValueError | DepictError):  # FrameError, PipelineError, UsageError, ...
        return str(exc)
    if isinstance(exc, FileNotFoundError):
        return f"no such file: {exc.filename or exc}"
    if isinstance(exc, OSError):  # a file that cannot be read or written
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror or exc}"
    if isinstance(exc, RecursionError):
        return "input nested too deeply"
    if isinstance(exc, MemoryError) or (
        type(exc).__module__ == "cv2" and "Insufficient memory" in str(exc)
    ):
        return (
            "out of memory: this run needs more memory than is free; set DEPICT_MAX_PIXELS or "
            "DEPICT_MAX_DECODED_MB to refuse files and renders that large before they start"
        )
    return None


def printable(text: str) -> str:
    """``text`` with control characters (ESC, newlines, ...) escaped as ``\\xNN``, so what a
    file names cannot move the cursor, recolour the terminal or add lines."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


def not_blank(hint: str) -> Any:
    """An argparse ``type``: any text but a blank one, which would stand for no option at all
    (an unset variable in ``--server "$FARM"`` ran the command here), or a one-line error
    ending with ``hint``."""

    def parse(text: str) -> str:
        if not text.strip():
            raise argparse.ArgumentTypeError(f"is empty; {hint}")
        return text

    return parse


#: An argparse ``type`` for a file to write (an empty name would name the current folder).
named_path = not_blank("give a file name")


def bounded(kind: type, low: float, high: float) -> Any:
    """An argparse ``type``: a number of ``kind`` within [low, high], or a one-line error."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {kind.__name__}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text} is not within [{low:g}, {high:g}]")
        return value

    return parse


def parse_value(text: str, *, whole: bool = True) -> Any:
    """A ``--set`` value: JSON when it parses (numbers, booleans, lists), a comma list of such
    values (``1,0.5,0.25``), else the plain string; ValueError for a whole value that opens a
    JSON list or object and does not parse (split at its commas, ``[0.5,nan]`` was said to hold
    ``'[0.5'``). A piece of a comma list may open with ``[`` (a mask's ``[ab]*``)."""
    try:
        return json.loads(text)
    except ValueError as exc:  # not JSON, or a number with more digits than Python converts
        if whole and text.startswith(("[", "{")):
            raise ValueError(f"{text!r} is not valid JSON ({exc})") from None
    if "," in text:
        return [parse_value(part, whole=False) for part in text.split(",")]
    return text


def parse_sets(items: list[str]) -> dict[str, dict[str, Any]]:
    """``section.key=value`` items -> ``{section: {key: value}}`` (values parsed as JSON)."""
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        lhs, sep, rhs = item.partition("=")
        section, dot, key = lhs.partition(".")
        if not sep or not dot or not key:
            raise UsageError(f"--set {item!r}: expected SECTION.KEY=VALUE")
        try:
            value = parse_value(rhs.strip())
        except ValueError as exc:
            raise UsageError(f"--set {item!r}: {exc}") from None
        out.setdefault(section.strip(), {})[key.strip()] = value
    return out


class _OpAction(argparse.Action):
    """``--op NAME`` starts a new pipeline step."""

    def __call__(
        self, parser: argparse.ArgumentParser, ns: Any, value: Any, option: Any = None
    ) -> None:
        steps = getattr(ns, "steps", None) or []
        steps.append({"op": value, "params": {}})
        ns.steps = steps


class _SetAction(argparse.Action):
    """``--set key=value`` sets a parameter of the last ``--op``."""

    def __call__(
        self, parser: argparse.ArgumentParser, ns: Any, value: Any, option: Any = None
    ) -> None:
        steps = getattr(ns, "steps", None)
        if not steps:
            parser.error("--set must follow an --op NAME")
        key, sep, raw = str(value).partition("=")
        if not sep or not key:
            parser.error(f"--set {value!r}: expected key=value")
        try:
            steps[-1]["params"][key.strip()] = parse_value(raw.strip())
        except ValueError as exc:
            parser.error(f"--set {value!r}: {exc}")


def add_pipeline_options(p: argparse.ArgumentParser, what: str = "a pipeline step") -> None:
    """``--op NAME [--set k=v ...] ...`` or ``--pipeline PIPE.json``."""
    p.add_argument("--op", action=_OpAction, metavar="NAME", help=f"add {what}")
    p.add_argument(
        "--set", action=_SetAction, metavar="KEY=VALUE", help="a parameter of the last --op"
    )
    p.add_argument("--pipeline", metavar="PIPE.json", help="pipeline JSON instead of --op")


class LazyHelp(str):
    """A help text made when argparse shows it (it formats ``help % params``), so that what
    making it imports costs building the parser (``depict --help``) nothing."""

    make: Callable[[], str]

    def __new__(cls, make: Callable[[], str]) -> LazyHelp:
        text = super().__new__(cls, make.__name__)
        text.make = make
        return text

    def __mod__(self, params: Any) -> str:
        return self.make() % params


def _preset_help() -> str:
    from gbuffer.presets import preset_help

    return preset_help()


def add_read_options(p: argparse.ArgumentParser) -> None:
    """Flags for reading a frame: preset, camera and mapping overrides."""
    p.add_argument(
        "--preset",
        default="auto",
        help=LazyHelp(_preset_help),
    )
    p.add_argument("--camera", metavar="CAM.json", help="camera JSON (overrides the file's)")
    p.add_argument(
        "--map",
        action="append",
        default=[],
        metavar="BUFFER=CHANNELS",
        help="map a canonical buffer to file channels, e.g. normal=MyLayer.N or depth=Z",
    )
    p.add_argument(
        "--normal-space", choices=["world", "camera"], help="override the normals' space"
    )
    p.add_argument(
        "--view-layer",
        metavar="NAME",
        help="the view layer whose passes are read, of a render with several (Blender's; "
        "default: the one with the most passes)",
    )
    p.add_argument(
        "--colorspace",
        metavar="NAME",
        help="working space of the radiance, a linear colour space of the OpenColorIO config "
        "($OCIO, else the built-in studio config), e.g. ACEScg or lin_rec709 (default: the "
        "file's chromaticities, else the preset's, else linear Rec.709)",
    )


#: ``--layout`` choices (:data:`gbuffer.io.LAYOUTS`, named here so the parser stays light).
LAYOUTS = ("same", "part", "sidecar")
DEFAULT_LAYOUT = "part"


def add_write_options(p: argparse.ArgumentParser) -> None:
    """Flags for writing an enhanced frame: debug layers, result layer, layout."""
    p.add_argument("--debug-layers", action="store_true", help="also write intermediate layers")
    p.add_argument("--output-layer", metavar="NAME", help="write NAME.R/G/B/A instead of R,G,B,A")
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=DEFAULT_LAYOUT,
        help="where new layers go: same (the input's part, re-encoded), part (an added part of "
        "a multi-part file; the input's parts copied as they are), sidecar (a file with only "
        f"the new layers); default {DEFAULT_LAYOUT}",
    )


def mapping(args: argparse.Namespace) -> dict[str, str]:
    """The ``--map BUFFER=CHANNELS`` items, by buffer."""
    out = {}
    for item in args.map:
        key, sep, value = item.partition("=")
        if not sep:
            raise UsageError(f"--map {item!r}: expected BUFFER=CHANNELS")
        if key.strip() in out:  # (the last one was taken, without a word)
            raise UsageError(f"--map {item!r}: {key.strip()} is mapped twice; give it once")
        out[key.strip()] = value.strip()
    return out


def add_server_option(p: argparse.ArgumentParser) -> None:
    """``--server URL``: run the command on a Depict server instead of locally."""
    p.add_argument(
        "--server",
        metavar="URL",
        default=os.environ.get("DEPICT_SERVER", "").strip() or None,
        type=not_blank("give the server's URL, or leave --server out to run here"),
        help="run on this Depict server (env DEPICT_SERVER; key from DEPICT_API_KEY)",
    )
