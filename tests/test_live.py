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
from test_corridor import DRIVER_LIKE, _corridor_meta

from helpers import skip_path_weights
from terrapref.cli import main
from terrapref.interop.mcap_export import TOPICS
from terrapref.interop.ros_messages import typestore
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner.costmap import LETHAL_COST

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


def test_evaluate_live_serves_the_export_channels_to_a_websocket_client(tmp_path):
    """The same run is also written as MCAP (--mcap): its costmaps, as OccupancyGrid and as
    Foxglove Grid, once a second, are the ones the live view sent."""
    from test_costmap import _costmaps_in

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _corridor_meta(DRIVER_LIKE))
    port, got = _free_port(), {}
    client = threading.Thread(target=_watch, args=(port, got), daemon=True)
    client.start()
    assert main(["evaluate", str(model), "fig7_rock_vs_non_traversable_left", "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev"),
                 "--live", "--live-port", str(port), "--mcap"]) == 0
    client.join(timeout=30)
    counts, file_cost = _costmaps_in(tmp_path / "ev" / "runs" / "fig7_rock_vs_non_traversable_left_seed0.mcap")
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
    assert odom == sorted(odom) and odom[-1] > 50  # the run, as it went, to the end of the path


def test_a_port_in_use_is_one_line(tmp_path, capsys):
    from helpers import linear_model, one_line_error

    model = linear_model(tmp_path / "linear.safetensors")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert main(["evaluate", str(model), "fig7_rock_vs_non_traversable_left", "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev"),
                     "--live", "--live-port", str(port)]) == 2
    one_line_error(capsys, f"127.0.0.1:{port}", "cannot serve the live view")
