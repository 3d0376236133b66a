"""``depict batch``: frame patterns, ranges, a real Dask cluster on loopback and the local default.

12 small frames (canonical EXRs rendered with OSMesa, brightness varying per frame, one of them
corrupt) run on a ``dask scheduler`` + 2 ``dask worker`` processes started here, and on the
embedded local cluster. The corrupt frame is reported, the others are written, the exit code
says a frame failed, and every output equals a local enhance with the pinned statistics.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import trimesh

from gbuffer.exr import read_layout
from gbuffer.io import write
from gbuffer.render import render
from service.batch import BatchError, expand, find_frames, parse_frames, run_batch
from service.cli import main as cli
from service.enhance import enhance
from service.pipeline import DEFAULT_PIPELINE, compile
from tests.live_server import free_port

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
FRAMES = range(1, 13)
BAD = 7
RADIANCE = ("beauty", "ambient", "diffuse", "specular", "ambient.light", "diffuse.light")
RADIANCE += ("specular.light",)


# -- patterns and ranges -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("pattern", "frame", "name"),
    [
        ("shot.####.exr", 7, "shot.0007.exr"),
        ("shot.#.exr", 12, "shot.12.exr"),
        ("shot.%04d.exr", 7, "shot.0007.exr"),
        ("shot.%d.exr", 7, "shot.7.exr"),
        ("shot.@.exr", 7, "shot.7.exr"),
        ("shot.@@@.exr", 7, "shot.007.exr"),
        ("/a/b_####_c.exr", 12345, "/a/b_12345_c.exr"),
        ("s.####.exr", -3, "s.-0003.exr"),
    ],
)
def test_expand(pattern: str, frame: int, name: str) -> None:
    assert expand(pattern, frame) == name


@pytest.mark.parametrize("pattern", ["shot.exr", "a.####.b.####.exr", "a.%04d.@.exr"])
def test_expand_refuses_patterns_without_one_token(pattern: str) -> None:
    with pytest.raises(BatchError, match="token"):
        expand(pattern, 1)


def test_parse_frames() -> None:
    assert parse_frames("1-10x3") == [1, 4, 7, 10]
    assert parse_frames("5") == [5]
    assert parse_frames("1-3,10,2-4") == [1, 2, 3, 10, 4]
    assert parse_frames("1-100x2")[-1] == 99 and len(parse_frames("1-100x2")) == 50
    assert parse_frames("-2-1") == [-2, -1, 0, 1]
    for bad, words in [("a-b", "not FRAME"), ("5-1", "ends before"), ("1-9x0", "step")]:
        with pytest.raises(BatchError, match=words):
            parse_frames(bad)


def test_find_frames(tmp_path: Path) -> None:
    for name in (
        "s.0001.exr",
        "s.0002.exr",
        "s.0010.exr",
        "s.12.exr",
        "s.0003.exr.tmp",
        "t.0004.exr",
    ):
        (tmp_path / name).write_bytes(b"")
    assert find_frames(str(tmp_path / "s.####.exr")) == [1, 2, 10]
    assert find_frames(str(tmp_path / "s.%d.exr")) == [12]


# -- sequences ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``in/shot.####.exr`` frames 1-12; the light grows with the frame; frame 7 is corrupt."""
    root = tmp_path_factory.mktemp("seq")
    (root / "in").mkdir()
    frame = render(trimesh.creation.icosphere(subdivisions=2), 64, 48)
    for f in FRAMES:
        path = root / "in" / f"shot.{f:04d}.exr"
        if f == BAD:
            path.write_bytes(b"\x76\x2f\x31\x01 corrupt frame")
            continue
        copy = frame.copy()
        copy.outputs = {}  # written from the buffers
        for name in RADIANCE:  # a light that brightens: the statistics change per frame
            copy.buffers[name] = frame.buffers[name] * np.float32(0.5 + 0.1 * f)
        write(copy, path)
    return root


def check_outputs(root: Path, out: str, pinned: dict[str, float]) -> None:
    """Every good frame written, equal to a local enhance with the pinned statistics."""
    spec = compile(DEFAULT_PIPELINE)
    for f in FRAMES:
        path = Path(expand(out, f))
        assert path.exists() == (f != BAD), f
    for f in (2, 12):  # frames that did not measure: they used the pinned values
        mine = root / f"check.{f}.exr"
        enhance(str(root / "in" / f"shot.{f:04d}.exr"), str(mine), spec, pinned=pinned)
        assert mine.read_bytes() == Path(expand(out, f)).read_bytes()


@pytest.fixture(scope="module")
def dask_cluster() -> Iterator[str]:
    """A real ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    common = {"cwd": ROOT, "env": env, "start_new_session": True}
    procs = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "scheduler",
                *("--host", "127.0.0.1", "--port", str(port)),
                *("--no-dashboard", "--dashboard-address", "127.0.0.1:0"),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            **common,  # type: ignore[arg-type]
        )
    ]
    for _ in range(2):
        procs.append(
            subprocess.Popen(
                [
                    str(BIN / "dask"),
                    *("worker", address, "--nthreads", "1", "--no-dashboard"),
                    *("--host", "127.0.0.1", "--no-nanny"),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                **common,  # type: ignore[arg-type]
            )
        )
    try:
        from distributed import Client

        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(address, timeout="5s") as client:
                    client.wait_for_workers(2, timeout=60)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.3)
        yield address
    finally:
        for p in reversed(procs):  # workers first; SIGINT: dask closes at once (SIGTERM lingers)
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_batch_on_a_dask_cluster(
    sequence: Path, dask_cluster: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(sequence / "dask" / "rs.####.exr")
    pins = sequence / "dask" / "pins.json"
    code = cli(
        [
            *("batch", str(sequence / "in" / "shot.####.exr"), "-o", out, "--frames", "1-12"),
            *("--scheduler", dask_cluster, "--pinned", str(pins), "--no-progress"),
        ]
    )
    printed = capsys.readouterr().out
    assert code == 1  # frame 7 failed
    assert "11 done, 0 skipped, 1 failed (of 12 frames)" in printed
    assert f"frame {BAD} failed:" in printed and "shot.0007.exr" in printed
    pinned = json.loads(pins.read_text())
    check_outputs(sequence, out, pinned)

    # again with --skip-existing: nothing left to do but the failed frame and two outputs cut
    # off (an empty and a truncated one counted as done)
    whole = Path(expand(out, 3)).read_bytes()
    Path(expand(out, 3)).write_bytes(whole[: len(whole) // 2])
    Path(expand(out, 4)).write_bytes(b"")
    code = cli(
        [
            *("batch", str(sequence / "in" / "shot.####.exr"), "-o", out, "--skip-existing"),
            *("--scheduler", dask_cluster, "--pinned", str(pins), "--no-progress"),
        ]
    )
    assert code == 1
    assert "2 done, 9 skipped, 1 failed" in capsys.readouterr().out
    assert Path(expand(out, 3)).read_bytes() == whole
    read_layout(expand(out, 4))  # whole again


def test_batch_on_the_local_default(sequence: Path) -> None:
    out = str(sequence / "local" / "rs.%04d.exr")
    good = [f for f in FRAMES if f != BAD]
    summary = run_batch(
        str(sequence / "in" / "shot.####.exr"),
        out,
        steps=compile(DEFAULT_PIPELINE),
        frames=None,  # every existing input
        workers=2,
        progress=False,
    )
    assert summary.done == good and list(summary.failed) == [BAD]
    assert "shot.0007.exr" in summary.failed[BAD]
    check_outputs(sequence, out, summary.pinned)
    if summary.pinned:  # the brighter frame 12 alone would have measured other values
        alone = sequence / "alone.exr"
        spec = compile(DEFAULT_PIPELINE)
        measured = enhance(str(sequence / "in" / "shot.0012.exr"), str(alone), spec)
        assert measured["measured"] != summary.pinned
        assert alone.read_bytes() != Path(expand(out, 12)).read_bytes()


def test_frames_read_ahead_are_enhanced_where_they_were_read_or_reported(sequence: Path) -> None:
    """While frame 1 measures the statistics the other worker reads the next frame ahead: the
    corrupt one (reported as failed, the sequence goes on) and a good one (written, the same
    bytes as a local enhance with the pinned statistics)."""
    out = str(sequence / "ahead" / "rs.%04d.exr")
    for order in ([1, BAD, 2], [1, 2, BAD]):
        summary = run_batch(
            str(sequence / "in" / "shot.####.exr"),
            out,
            steps=compile(DEFAULT_PIPELINE),
            frames=order,
            workers=2,
            progress=False,
        )
        assert summary.done == [1, 2] and list(summary.failed) == [BAD]
        assert "shot.0007.exr" in summary.failed[BAD]
        mine = sequence / "ahead" / "check.exr"
        spec = compile(DEFAULT_PIPELINE)
        enhance(str(sequence / "in" / "shot.0002.exr"), str(mine), spec, pinned=summary.pinned)
        assert mine.read_bytes() == Path(expand(out, 2)).read_bytes()


def test_batch_refuses_bad_arguments(sequence: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = str(sequence / "in" / "shot.####.exr")
    assert cli(["batch", src, "-o", src]) == 2
    assert "output pattern is the input pattern" in capsys.readouterr().err
    assert cli(["batch", src, "-o", str(sequence / "x.exr")]) == 2
    assert "no frame token" in capsys.readouterr().err
    assert cli(["batch", str(sequence / "none.####.exr"), "-o", str(sequence / "o.####.exr")]) == 2
    assert "no frames" in capsys.readouterr().err
    assert cli(["batch", src, "-o", str(sequence / "o.####.exr"), "--op", "nope"]) == 2
    assert "unknown operator" in capsys.readouterr().err
    cores = os.cpu_count() or 1
    for workers in ("0", str(4 * cores + 1)):  # (1000 started 1000 worker processes)
        assert cli(["batch", src, "-o", str(sequence / "o.####.exr"), "--workers", workers]) == 2
        assert f"--workers {workers}: give 1 to {4 * cores}" in capsys.readouterr().err
    assert not (sequence / "o.0001.exr").exists()
    # checked once, not by each frame (exit 1, a line per frame)
    out = str(sequence / "o.####.exr")
    assert cli(["batch", src, "-o", out, "--output-layer", ""]) == 2
    assert "output layer '' is not a layer name" in capsys.readouterr().err
    assert cli(["batch", src, "-o", out, "--frames="]) == 2  # (it was every frame)
    assert "--frames '': '' is not FRAME" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:  # (it started a local one)
        cli(["batch", src, "-o", out, "--scheduler", ""])
    assert stop.value.code == 2
    assert "--scheduler: is empty; give the scheduler's address" in capsys.readouterr().err
    # (true was 1; 1e308 became inf in float32; 0, -1, 1e-300 failed every frame; a 401-digit
    # integer was an OverflowError traceback)
    for value in ("true", "1e308", "0", "-1", "1e-300", "1" + "0" * 400):
        pinned = sequence / "pinned.json"
        pinned.write_text(f'{{"radiance_scaling.white": {value}}}')
        assert cli(["batch", src, "-o", out, "--pinned", str(pinned)]) == 2
        assert "each positive and finite in float32" in capsys.readouterr().err
        pinned.unlink()
    assert not (sequence / "o.0001.exr").exists()


def test_a_statistic_the_pins_lack_is_measured_with_a_warning(sequence: Path) -> None:
    """A stale or hand-edited --pinned file (a key misspelt): the statistic it lacks was
    measured on every frame without a word, and flickered along the sequence."""
    pins = sequence / "typo.json"
    spec = compile(DEFAULT_PIPELINE)
    keys = enhance(str(sequence / "in" / "shot.0001.exr"), str(sequence / "k.exr"), spec)
    assert keys["measured"], "the default pipeline measures a statistic to pin"
    pins.write_text(json.dumps({f"{key}x": 1.0 for key in keys["measured"]}))
    summary = run_batch(
        str(sequence / "in" / "shot.####.exr"),
        str(sequence / "typo" / "rs.####.exr"),
        steps=spec,
        frames=[1, 2],
        workers=1,
        progress=False,
        pinned_file=pins,
    )
    assert summary.done == [1, 2]
    (warning, frames), *_ = summary.warnings.items()
    assert sorted(frames) == [1, 2]
    assert warning.startswith("statistics measured on each frame, not pinned: ")
    assert all(key in warning for key in keys["measured"])
    assert f"the pinned statistics {pins} lack" in warning
