"""The live view (terrapref.interop.live): `evaluate --live` serves the MCAP export's channels on
Foxglove's WebSocket protocol; a WebSocket client subscribes and decodes what it receives."""

from __future__ import annotations

import io
import json
import socket
import struct
import threading
import time

import numpy as np
import pytest
from PIL import Image
from test_offset_rule import DRIVER_LIKE, _offset_meta

from helpers import TINY_COURSE, skip_path_weights
from terrapref.cli import main
from terrapref.groundmap.costmap import LETHAL_COST
from terrapref.interop.mcap_export import TOPICS
from terrapref.interop.ros_messages import typestore
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig

websockets = pytest.importorskip("websockets.sync.client", reason="the WebSocket client of the tests (websockets) is not installed")
WATCHED = ("/terrapref/labels", "/terrapref/costmap", "/terrapref/costmap_grid", "/terrapref/trajectories", "/tf_static", "/terrapref/odom")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _watch(port: int, got: dict) -> None:
    """Connect (retrying while the server starts), subscribe to WATCHED and keep what arrives,
    by topic, until the server closes."""
    for _ in range(200):
        try:
            ws = websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], open_timeout=1, max_size=2**22)
            break
        except OSError:
            time.sleep(0.05)
    else:
        got["error"] = "no server"
        return
    channels: dict[int, dict] = {}
    with ws:
        try:
            for raw in ws:
                if isinstance(raw, str):
                    msg = json.loads(raw)
                    got.setdefault("ops", []).append(msg["op"])
                    if msg["op"] == "advertise":
                        channels.update({c["id"]: c for c in msg["channels"]})
                        wanted = [c for c in msg["channels"] if c["topic"] in WATCHED]
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in wanted]}))
                    continue
                opcode, sub, log_ns = struct.unpack_from("<BIQ", raw)
                if opcode == 1:  # message data
                    got.setdefault(channels[sub]["topic"], []).append((log_ns, bytes(raw[13:])))
        except websockets.ConnectionClosed:
            pass
    got["channels"] = channels


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_evaluate_live_serves_the_export_channels_to_a_websocket_client(tmp_path):
    """The same run is also written as MCAP (--mcap): its costmaps, as OccupancyGrid and as
    Foxglove Grid, once a second, are the ones the live view sent."""
    from test_costmap import _costmaps_in

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    port, got = _free_port(), {}
    client = threading.Thread(target=_watch, args=(port, got), daemon=True)
    client.start()
    assert (
        main(
            [
                "evaluate",
                str(model),
                str(TINY_COURSE),
                "--seeds",
                "1",
                "--no-driver",
                "--out",
                str(tmp_path / "ev"),
                "--live",
                "--live-port",
                str(port),
                "--mcap",
            ]
        )
        == 0
    )
    client.join(timeout=30)
    (run,) = (tmp_path / "ev" / "runs").glob("*tiny_course_seed0.mcap")  # named after the course file's path
    counts, file_cost = _costmaps_in(run)
    assert counts["/terrapref/costmap"] == counts["/terrapref/costmap_grid"] == -(-counts["/terrapref/labels"] // 10)  # once a second
    assert "error" not in got and got["ops"][:2] == ["serverInfo", "advertise"]
    advertised = {c["topic"]: c for c in got["channels"].values()}
    assert set(advertised) == {topic for topic, _ in TOPICS.values()}
    assert all(c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg" for c in advertised.values())
    ts = typestore()

    def decoded(topic: str) -> list:
        return [ts.deserialize_cdr(data, advertised[topic]["schemaName"]) for _, data in got[topic]]

    labels = decoded("/terrapref/labels")
    assert len(labels) > 20 and labels[-1].header.frame_id == "camera_optical"
    ids = np.asarray(Image.open(io.BytesIO(labels[-1].data.tobytes())))
    assert ids.shape == (480, 640) and set(np.unique(ids).tolist()) <= {0, 1, 2, 3, 4, 255}
    grid = decoded("/terrapref/costmap")[-1]
    cost = np.asarray(grid.data, dtype=np.int8).reshape(grid.info.height, grid.info.width)
    assert (cost == LETHAL_COST).any() and ((cost > 0) & (cost < LETHAL_COST)).any() and grid.header.frame_id == "odom"
    np.testing.assert_array_equal(cost, file_cost)  # the last one sent is the file's last
    foxglove_grid = decoded("/terrapref/costmap_grid")[-1]
    assert foxglove_grid.column_count == grid.info.width and len(foxglove_grid.data) == cost.size * foxglove_grid.cell_stride
    markers = decoded("/terrapref/trajectories")[-1].markers
    assert len(markers) == 21 and sum(m.scale.x > 0.05 for m in markers) == 1  # the chosen one is drawn thick
    assert {t.child_frame_id for t in decoded("/tf_static")[-1].transforms} == {"camera_link", "camera_optical"}
    odom = [m.pose.pose.position.x for m in decoded("/terrapref/odom")]
    assert odom == sorted(odom) and odom[-1] > 11  # the run, as it went, to its goal (within 2 m of x = 14 m)


def test_a_port_in_use_is_one_line(tmp_path, capsys):
    from helpers import linear_model, one_line_error

    model = linear_model(tmp_path / "linear.safetensors")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert (
            main(
                [
                    "evaluate",
                    str(model),
                    "fig7_rock_vs_non_traversable_left",
                    "--seeds",
                    "1",
                    "--no-driver",
                    "--out",
                    str(tmp_path / "ev"),
                    "--live",
                    "--live-port",
                    str(port),
                ]
            )
            == 2
        )
    one_line_error(capsys, f"127.0.0.1:{port}", "cannot serve the live view")


@pytest.mark.parametrize("host", ["192.0.2.1", "no-such-host.invalid"])  # an address of no interface here (TEST-NET-1); a name of none
def test_a_host_this_machine_cannot_listen_on_blames_the_host(tmp_path, capsys, host):
    from helpers import linear_model, one_line_error

    model = linear_model(tmp_path / "linear.safetensors")
    assert (
        main(
            [
                "evaluate",
                str(model),
                str(TINY_COURSE),
                "--seeds",
                "1",
                "--no-driver",
                "--out",
                str(tmp_path / "ev"),
                "--live",
                "--live-host",
                host,
            ]
        )
        == 2
    )
    assert "--live-port" not in one_line_error(capsys, f"{host}: --live-host: cannot listen on this address")


@pytest.mark.parametrize(
    "offered,named",
    [
        (["foxglove.websocket.v1"], "foxglove.websocket.v1"),
        (["foxglove.sdk.v1"], "foxglove.sdk.v1"),
        (["foxglove.websocket.v1", "foxglove.sdk.v1"], "foxglove.sdk.v1"),
    ],
)
def test_a_viewer_connects_by_either_name_of_the_protocol(offered, named):
    from terrapref.interop.live import LiveView

    view = LiveView(port=0)
    try:
        with websockets.connect(view.url, subprotocols=offered, open_timeout=5) as ws:
            assert ws.subprotocol == named and json.loads(ws.recv(timeout=5))["op"] == "serverInfo"
    finally:
        view.stop()


def test_a_client_offering_neither_name_is_told_which_the_view_speaks():
    from websockets.exceptions import InvalidStatus

    from terrapref.interop.live import LiveView

    view = LiveView(port=0)
    try:
        for offered in (None, ["some.other.v1"]):
            with pytest.raises(InvalidStatus) as refused:
                websockets.connect(view.url, subprotocols=offered, open_timeout=5)
            response = refused.value.response
            assert response.status_code == 400 and response.headers["Sec-WebSocket-Protocol"] == "foxglove.sdk.v1, foxglove.websocket.v1"
            assert b"speaks the subprotocol foxglove.sdk.v1 (also by its earlier name foxglove.websocket.v1)" in response.body
    finally:
        view.stop()


def test_a_paced_run_sends_each_frame_when_its_time_comes(monkeypatch):
    from types import SimpleNamespace

    from terrapref.interop import live

    clock, slept = [100.0], []
    monkeypatch.setattr(live.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(live.time, "sleep", lambda s: slept.append(round(s, 6)))
    run = live.LiveRun(SimpleNamespace(pace=2.0), scene=None)
    for t_s, wall in ((5.0, 100.0), (6.0, 100.1), (8.0, 101.6)):  # run time [s], then the wall clock when the frame is ready
        clock[0] = wall
        run._keep_pace(t_s)
    assert slept == [0.4]  # 1 s of run at twice real time is due 0.5 s after the first; the third frame was late already
    unpaced = live.LiveRun(SimpleNamespace(pace=0.0), scene=None)
    unpaced._keep_pace(0.0)
    unpaced._keep_pace(10.0)
    assert slept == [0.4]


def test_wait_holds_the_first_run_until_a_viewer_subscribes():
    from terrapref.camera import CameraConfig
    from terrapref.features import PreferenceSetConfig
    from terrapref.interop.live import LiveRun, LiveView
    from terrapref.terrain import default_classes

    view = LiveView(port=0, wait=True)
    started = threading.Event()
    runner = threading.Thread(
        target=lambda: (
            LiveRun.start(view, np.array([[0.0, 0.0], [5.0, 0.0]]), CameraConfig(), default_classes(), PreferenceSetConfig()),
            started.set(),
        ),
        daemon=True,
    )
    try:
        runner.start()
        assert not started.wait(0.3)  # no viewer yet
        with websockets.connect(view.url, subprotocols=["foxglove.websocket.v1"], open_timeout=5) as ws:
            advertised = next(m for m in (json.loads(ws.recv(timeout=5)) for _ in range(5)) if m["op"] == "advertise")
            channel = advertised["channels"][0]["id"]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel}]}))
            assert started.wait(10)
    finally:
        view.stop()


def test_live_pace_and_wait_go_with_live(tmp_path, capsys):
    from helpers import linear_model, one_line_error

    model = linear_model(tmp_path / "linear.safetensors")
    base = ["evaluate", str(model), "demo_course", "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev")]
    assert main([*base, "--live-pace", "1"]) == 2
    one_line_error(capsys, "--live-pace: goes with --live")
    for flag, value in (("--live-port", "99999"), ("--live-host", "0.0.0.0")):  # an address for a view not asked for
        assert main([*base, flag, value]) == 2
        one_line_error(capsys, f"{flag}: goes with --live")
    assert main([*base, "--live", "--live-port", "0", "--live-pace", "0"]) == 2
    one_line_error(capsys, "--live-pace: expected a factor of real time > 0")
    assert not (tmp_path / "ev").exists()
