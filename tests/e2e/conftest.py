"""The servers under test and the files they are sent, started and made once for the package."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import trimesh

from gbuffer.io import write as write_exr
from gbuffer.render import render
from tests.e2e.common import KEY, MAX_PIXELS, MAX_UPLOAD_MB
from tests.live_server import Server, live_servers


@pytest.fixture(scope="package")
def servers() -> Iterator[dict[str, Server]]:
    """The server under test, and one whose jobs always pass their time limit (504); both
    start at once, so their start-up times overlap."""
    main = {
        "DEPICT_API_KEY": KEY,
        "DEPICT_WORKERS": "2",
        "DEPICT_QUEUE": "2",
        "DEPICT_MAX_PIXELS": str(MAX_PIXELS),
        "DEPICT_MAX_UPLOAD_MB": str(MAX_UPLOAD_MB),
        "DEPICT_TIMEOUT_S": "120",
    }
    slow = {"DEPICT_WORKERS": "1", "DEPICT_QUEUE": "1", "DEPICT_TIMEOUT_S": "0.001"}
    with live_servers({"main": main, "slow": slow}) as servers:
        yield servers


@pytest.fixture(scope="package")
def server(servers: dict[str, Server]) -> Server:
    return servers["main"]


@pytest.fixture(scope="package")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A canonical EXR (OSMesa render of an icosphere), a larger one, and a mesh."""
    root = tmp_path_factory.mktemp("e2e")
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.export(root / "ico.obj")
    write_exr(render(mesh, 160, 120), root / "canonical.exr")
    write_exr(render(mesh, 640, 480), root / "big.exr")
    return {"canonical": root / "canonical.exr", "big": root / "big.exr", "mesh": root / "ico.obj"}


@pytest.fixture
def remote_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEPICT_API_KEY", KEY)
    monkeypatch.delenv("DEPICT_SERVER", raising=False)
