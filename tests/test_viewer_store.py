"""The viewer's frame store: a time to live after the last use, a size cap and a count cap with
the least recently used frame going first, folders removed with their frames. On the store
itself (real folders) and through a real ``depict serve`` whose limits are small."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from service.enhance import ReadRequest
from service.problems import Problem
from service.viewer.store import FrameStore, StoredFrame
from tests.live_server import live_server

BLENDER = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"


def put(store: FrameStore, size: int) -> StoredFrame:
    with store.new_folder() as (frame_id, folder):
        (folder / "in.exr").write_bytes(b"x" * size)
        frame = StoredFrame(frame_id, folder, "f.exr", ReadRequest(), size)
        store.admit(frame)
        return frame


def test_least_recently_used_goes_first_when_the_size_cap_is_reached(tmp_path: Path) -> None:
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=300, max_frames=10)
    a, b = put(store, 100), put(store, 100)
    put(store, 100)
    store.get(a.id)  # a is now more recent than b
    d = put(store, 100)
    assert b.id not in store and not b.folder.exists()
    assert a.id in store and d.id in store
    assert store.used_bytes == 300 and len(store) == 3


def test_count_cap_and_a_frame_over_the_size_cap(tmp_path: Path) -> None:
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=1000, max_frames=2)
    a = put(store, 10)
    put(store, 10)
    put(store, 10)
    assert a.id not in store and len(store) == 2
    with pytest.raises(Problem) as err:
        put(store, 2000)
    assert err.value.kind == "limit" and "DEPICT_VIEWER_MAX_MB" in err.value.detail
    assert len(list(tmp_path.iterdir())) == 2  # the refused upload's folder is gone too


def test_frames_expire_after_their_last_use(tmp_path: Path) -> None:
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=1000, max_frames=10)
    old, fresh = put(store, 10), put(store, 10)
    old.last_used -= 61  # as if unused for 61 s
    store.get(fresh.id)
    assert old.id not in store and not old.folder.exists() and fresh.folder.exists()
    with pytest.raises(Problem) as err:
        store.get(old.id)
    assert err.value.kind == "not-found" and "upload it again" in err.value.detail


def test_a_failed_upload_leaves_no_folder(tmp_path: Path) -> None:
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=1000, max_frames=10)
    with pytest.raises(OSError), store.new_folder() as (_, folder):
        (folder / "in.exr").write_bytes(b"partial")
        raise OSError("the client went away")
    assert not list(tmp_path.iterdir()) and len(store) == 0


def test_unknown_and_malformed_ids_are_not_found(tmp_path: Path) -> None:
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=1000, max_frames=10)
    for bad in ("../../etc", "", "x" * 100, "A" * 22):
        with pytest.raises(Problem) as err:
            store.get(bad)
        assert err.value.kind == "not-found"
    frame = put(store, 10)
    store.remove(frame.id)
    assert frame.id not in store and not frame.folder.exists()


def test_live_server_keeps_at_most_its_frames_and_forgets_on_request() -> None:
    env = {"DEPICT_WORKERS": "1", "DEPICT_VIEWER_MAX_FRAMES": "2", "DEPICT_VIEWER_MAX_MB": "2"}
    with live_server(env) as server, httpx.Client(base_url=server.url, timeout=60) as api:

        def upload() -> str:
            with open(BLENDER, "rb") as f:
                r = api.post("/v1/frames", files={"file": (BLENDER.name, f)})
            assert r.status_code == 200, r.text
            return str(r.json()["id"])

        first, second = upload(), upload()
        assert api.get(f"/v1/frames/{first}").status_code == 200  # first is now the most recent
        third = upload()
        assert api.get(f"/v1/frames/{second}").status_code == 404  # the least recently used
        assert api.get(f"/v1/frames/{first}").status_code == 200
        assert api.delete(f"/v1/frames/{third}").status_code == 204
        assert api.get(f"/v1/frames/{third}").status_code == 404


def test_live_server_refuses_a_frame_over_the_size_cap() -> None:
    env = {"DEPICT_WORKERS": "1", "DEPICT_VIEWER_MAX_MB": "0.5"}
    with live_server(env) as server:
        with open(BLENDER, "rb") as f:
            r = httpx.post(f"{server.url}/v1/frames", files={"file": (BLENDER.name, f)}, timeout=60)
        assert r.status_code == 413, r.text
        assert "DEPICT_VIEWER_MAX_MB" in r.json()["detail"]


@pytest.mark.parametrize(("route", "height", "factor"), [("example", 180, 4), ("upload", 60, 2)])
def test_a_loaded_frame_comes_with_its_copy_at_the_pages_preview_height(
    route: str, height: int, factor: int, tmp_path: Path
) -> None:
    """The page sends its preview height with the frame (``?height=``): the copy its first
    previews run on is made as the frame is inspected, at that height (the example's own
    height, 720 px, once hid the one asked for)."""
    env = {"DEPICT_WORKERS": "1", "TMPDIR": str(tmp_path)}  # (the server keeps frames there)
    with live_server(env) as server, httpx.Client(base_url=server.url, timeout=120) as api:
        if route == "example":
            r = api.post("/v1/frames/example", params={"height": height})
        else:
            with open(BLENDER, "rb") as f:
                r = api.post("/v1/frames", params={"height": height}, files={"file": f})
        assert r.status_code == 200, r.text
        made = sorted(p.name for p in tmp_path.glob(f"depict-*/**/{r.json()['id']}/small_*"))
        assert made == [f"small_{factor}.layers.pkl", f"small_{factor}.pkl"]
