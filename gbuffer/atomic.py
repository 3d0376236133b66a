"""Write files under a temporary name and rename them into place, so no reader ever sees half,
and never destroy what an output path names: an input, a special file, a symbolic link."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path

from gbuffer.errors import OutputError

# The process umask, read once at import (os.umask can only be read by setting it).
_UMASK = os.umask(0o022)
os.umask(_UMASK)

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def output_target(path: str | Path) -> Path:
    """The file an output ``path`` will replace: a symbolic link's target (the link stays, the
    file it points to gets the new content), the path itself otherwise.

    Raises :class:`OutputError` when that file exists and is not a regular file (a FIFO, a
    device such as ``/dev/null``, a socket, a directory): replacing it would destroy it.
    """
    _not_a_folder_name(path)
    given = Path(path)
    target = Path(os.path.realpath(given)) if given.is_symlink() else given
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return target
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    kind = special_kind(mode)
    if kind is not None:
        raise OutputError(
            f"cannot write {path}: it is {kind}, not a regular file; choose a file name"
        )
    return target


def _not_a_folder_name(path: str | Path) -> None:
    """:class:`OutputError` for an output named as a folder (``out/``): a file written there would
    take the folder's name."""
    if isinstance(path, str) and path.endswith(("/", os.sep)):
        raise OutputError(
            f"cannot write {path}: it names a folder (it ends in /); give a file name"
        )


def regular_file(path: str | Path) -> Path:
    """``path``, when it is a regular file (through links), else :class:`OSError`: missing, or
    "it is a FIFO (named pipe), not a regular file" and the like, said before it is opened (a
    FIFO with no writer would block the reader for ever)."""
    kind = special_kind(os.stat(path).st_mode)
    if kind is not None:
        raise OSError(errno.EINVAL, f"it is {kind}, not a regular file")
    return Path(path)


def read_text(path: str | Path) -> str:
    """The UTF-8 text of the regular file ``path`` (:func:`regular_file`)."""
    return regular_file(path).read_text(encoding="utf-8")


def special_kind(mode: int) -> str | None:
    """What a file of ``mode`` (``os.stat``) is when it is not a regular file ("a FIFO (named
    pipe)", "a directory", ...), else None."""
    return next((kind for test, kind in _KINDS if test(mode)), None)


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file: the same resolved path, or the same inode (hard links)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_outputs(
    outputs: Iterable[str | Path | None], inputs: Iterable[str | Path | None]
) -> None:
    """:class:`OutputError` when an output names an input (or another output), or a file that
    cannot be replaced (see :func:`output_target`). ``None`` entries are skipped."""
    ins = [Path(p) for p in inputs if p]
    seen: list[Path] = []
    for given in (p for p in outputs if p):
        output_target(given)  # (as given: a name ending in / is refused before Path drops it)
        out = Path(given)
        for other in ins:
            if same_file(out, other):
                raise OutputError(
                    f"output {out} is the input {other}: it would be overwritten; write elsewhere"
                )
        for other in seen:
            if same_file(out, other):
                raise OutputError(f"two outputs name the same file {out}; give distinct names")
        seen.append(out)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside the output; on success rename it over the output, else
    remove it.

    The output is :func:`output_target` of ``path`` (through symbolic links; special files are
    refused). The temporary name keeps the suffix of ``path`` (libraries choose formats by
    suffix). The file gets the mode of the file it replaces, else the usual ``0o666 & ~umask``
    (not the private 0600 of a temporary file). An :class:`OSError` (a folder that cannot be
    written, a full disk) becomes an :class:`OutputError` naming ``path``. Folders made for the
    output are removed again when it is not written (those still empty).
    """
    target = output_target(path)
    tmp_path: Path | None = None
    made = _missing_folders(target.parent)
    written = False
    try:
        for attempt in range(_ATTEMPTS):
            target.parent.mkdir(parents=True, exist_ok=True)
            # (named before it exists: a signal as it is made cannot orphan it)
            tmp_path = target.parent / f".{target.stem}.{secrets.token_hex(4)}.tmp{target.suffix}"
            try:  # (named as :func:`partial_files` finds it)
                os.close(os.open(tmp_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
                break
            except FileExistsError:  # (someone else's: never ours to remove)
                tmp_path = None
            except FileNotFoundError:  # (a new folder that another write failing removed)
                tmp_path = None
                if attempt == _ATTEMPTS - 1:
                    raise
            except OSError:  # (not made: nothing to remove)
                tmp_path = None
                raise
        else:
            raise FileExistsError(errno.EEXIST, "no free temporary name beside it")
        assert tmp_path is not None
        try:
            mode = target.stat().st_mode & 0o777
        except OSError:
            mode = 0o666 & ~_UMASK
        os.chmod(tmp_path, mode)
        yield tmp_path
        os.replace(tmp_path, target)
        written = True
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        if tmp_path is not None:
            with contextlib.suppress(OSError):  # (a read-only folder: EROFS even when missing)
                tmp_path.unlink(missing_ok=True)
        if not written:
            for folder in made:  # deepest first; one something else wrote into is not empty
                with contextlib.suppress(OSError):
                    folder.rmdir()


#: Tries at a free temporary name (and at the folder, made again if a concurrent write removed it).
_ATTEMPTS = 100


def _missing_folders(folder: Path) -> list[Path]:
    """``folder`` and those of its parents that do not exist, deepest first."""
    missing = []
    while not folder.exists() and folder.parent != folder:
        missing.append(folder)
        folder = folder.parent
    return missing


def partial_files(paths: Iterable[str | Path] | str | Path) -> list[Path]:
    """The temporary files :func:`atomic_path` made beside any of the outputs ``paths`` and did
    not get to remove (a process stopped while it wrote: e.g. a batch's worker ended with the
    batch); each folder listed once, names matched exactly (a user's ``.out.old.tmp.exr`` or
    another output's temporary file are not among them)."""
    wanted: dict[Path, set[str]] = {}
    for path in [paths] if isinstance(paths, str | Path) else paths:
        given = Path(path)  # (beside a link's target, as atomic_path writes)
        target = Path(os.path.realpath(given)) if given.is_symlink() else given
        wanted.setdefault(target.parent, set()).add(target.name)
    found = []
    for folder, names in wanted.items():
        found += [path for path, output in _temporaries(folder) if output in names]
    return sorted(found)


def partial_files_in(folder: str | Path) -> list[Path]:
    """Every temporary file :func:`atomic_path` made in ``folder`` and did not get to remove,
    whatever its output (a folder only Depict writes: a viewer frame's copies)."""
    return sorted(path for path, _ in _temporaries(Path(folder)))


def _temporaries(folder: Path) -> Iterator[tuple[Path, str]]:
    """The files in ``folder`` named as :func:`atomic_path` names a temporary file, each with
    the name of the output it was for (none when the folder cannot be read)."""
    with contextlib.suppress(OSError), os.scandir(folder) as entries:
        for entry in entries:
            made = _TEMPORARY.match(entry.name)
            if made is not None:
                yield folder / entry.name, made["stem"] + made["suffix"]


#: The name :func:`atomic_path` gives an output's temporary file: ``.{stem}.{8 hex}.tmp{suffix}``.
_TEMPORARY = re.compile(r"^\.(?P<stem>.+)\.[0-9a-f]{8}\.tmp(?P<suffix>.*)$", re.S)
