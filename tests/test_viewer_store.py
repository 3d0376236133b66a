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


def test_what_a_job_writes_is_counted_and_a_killed_jobs_temporary_files_go(
    tmp_path: Path,
) -> None:
    """When a frame's last running job ends, the copies it wrote count in the frame's bytes
    (older frames go past the cap), and a temporary file that a worker killed mid-write left
    beside them is removed."""
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=300, max_frames=10)
    a, b = put(store, 100), put(store, 100)
    with store.job(b), store.job(b):  # (two at once: counted when the second ends)
        (b.folder / "small_2.pkl").write_bytes(b"y" * 150)
        (b.folder / ".small_1.0a1b2c3d.tmp.pkl").write_bytes(b"half")
    assert sorted(p.name for p in b.folder.iterdir()) == ["in.exr", "small_2.pkl"]
    assert b.size_bytes == 250 and store.used_bytes == 250
    assert a.id not in store and not a.folder.exists()


def test_a_frame_a_job_runs_on_is_not_evicted(tmp_path: Path) -> None:
    """Another frame's copy passing the cap while a job runs on the older frame: the busy frame
    stays (its job would have lost its folder) until its job ends; the newest stays even when
    it alone is over the cap."""
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=300, max_frames=10)
    a, b = put(store, 100), put(store, 100)
    with store.job(a):
        with store.job(b):
            (b.folder / "small_2.pkl").write_bytes(b"y" * 150)
        assert a.id in store and a.folder.exists() and store.used_bytes == 350
    assert a.id not in store and not a.folder.exists() and b.id in store
    with store.job(b):
        (b.folder / "small_1.pkl").write_bytes(b"y" * 400)
    assert b.id in store and store.used_bytes == 650


def test_a_frame_forgotten_while_its_job_runs_leaves_no_folder(tmp_path: Path) -> None:
    """Deleted (or expired, or evicted) while a worker makes its copy: the worker's write makes
    the folder anew, and the job's end removes it again."""
    store = FrameStore(tmp_path, ttl_s=60, max_bytes=1000, max_frames=10)
    frame = put(store, 10)
    with store.job(frame):
        store.remove(frame.id)
        frame.folder.mkdir()  # (as the worker's atomic write does)
        (frame.folder / "small_1.pkl").write_bytes(b"z" * 100)
    assert not frame.folder.exists() and not list(tmp_path.iterdir())
    again = put(store, 10)
    with pytest.raises(Problem) as err, store.job(again):
        store.remove(again.id)
        raise OSError("cannot write small_1.layers.pkl: No such file or directory")
    assert err.value.kind == "not-found" and "forgotten while this job ran" in err.value.detail


def test_live_server_counts_the_copies_of_its_frames_in_its_cap(tmp_path: Path) -> None:
    """``DEPICT_VIEWER_MAX_MB`` holds the frames on disk, their preview copies included
    (eight times the upload, for this small file): the frames' folders stay under it."""
    env = {"DEPICT_WORKERS": "1", "DEPICT_VIEWER_MAX_MB": "20", "TMPDIR": str(tmp_path)}
    with live_server(env) as server, httpx.Client(base_url=server.url, timeout=60) as api:
        ids = []
        for _ in range(3):
            with open(BLENDER, "rb") as f:
                r = api.post("/v1/frames", files={"file": (BLENDER.name, f)})
            assert r.status_code == 200, r.text
            ids.append(r.json()["id"])
        kept = [api.get(f"/v1/frames/{i}").status_code for i in ids]
        assert kept == [404, 200, 200]
        on_disk = sum(p.stat().st_size for p in tmp_path.glob("depict-*/**/*") if p.is_file())
        assert on_disk <= 20 * 2**20


def test_live_server_keeps_at_most_its_frames_and_forgets_on_request() -> None:
    env = {"DEPICT_WORKERS": "1", "DEPICT_VIEWER_MAX_FRAMES": "2", "DEPICT_VIEWER_MAX_MB": "64"}
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
