"""Every EXR of a folder through ``depict``, as a user would run it: how each command ended.

``python -m bench.exr_samples DIR [--commands inspect preview enhance]`` runs each command on
every file under ``DIR`` (e.g. a checkout of OpenEXR's sample images, ``openexr-images``, with
its ``Damaged`` folder of fuzzed files) in a process of its own, with a time limit, and prints
one line per run: exit code, seconds, peak memory, the first line of what it printed on stderr.
Then the counts, and the runs that broke the rules of the command line: an exit code other than
0 and 2, a traceback, more than one line on stderr for an error, or the time limit. Its exit code
is 1 when there are any.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

COMMANDS = ("inspect", "preview", "enhance")
LIMIT_S = 60.0


def _argv(command: str, path: Path, out: Path) -> list[str]:
    cli = [sys.executable, "-m", "service.cli", command, str(path)]
    if command == "preview":
        return [*cli, "-o", str(out / "preview.png")]
    if command == "enhance":
        return [*cli, "-o", str(out / "enhanced.exr")]
    return cli


def run_one(command: str, path: Path, out: Path) -> tuple[int, float, int, str]:
    """(exit code, seconds, the child's peak memory in MiB, stderr); 124 past the limit."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        _argv(command, path, out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    timer = threading.Timer(LIMIT_S, proc.kill)
    timer.start()
    assert proc.stderr is not None
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)  # (this child's own resource usage)
    timer.cancel()
    code = proc.returncode = os.waitstatus_to_exitcode(status)
    if code == -signal.SIGKILL:
        code, err = 124, "time limit"
    return code, time.perf_counter() - t0, usage.ru_maxrss // 1024, err


def broken(code: int, err: str) -> bool:
    """Whether a run broke the command line's rules (see the module docstring)."""
    lines = err.strip().splitlines()
    return code not in (0, 2) or "Traceback" in err or (code == 2 and len(lines) != 1)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--commands", nargs="+", choices=COMMANDS, default=list(COMMANDS))
    args = ap.parse_args(argv)
    files = sorted(p for p in args.folder.rglob("*") if p.is_file() and ".git" not in p.parts)
    counts: Counter[tuple[str, int]] = Counter()
    bad: list[str] = []
    with tempfile.TemporaryDirectory(prefix="exr-samples-") as tmp:
        for path in files:
            for command in args.commands:
                code, secs, mib, err = run_one(command, path, Path(tmp))
                first = (err.strip().splitlines() or [""])[0][:160]
                line = f"{code:3d} {secs:6.2f} s {mib:6d} MiB  {command:8s} {path}  {first}"
                print(line, flush=True)
                counts[(command, code)] += 1
                if broken(code, err):
                    bad.append(line)
    print(f"\n{len(files)} files")
    for (command, code), n in sorted(counts.items()):
        print(f"  {command:8s} exit {code}: {n}")
    print(f"runs that broke the rules: {len(bad)}")
    for line in bad:
        print("  " + line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
