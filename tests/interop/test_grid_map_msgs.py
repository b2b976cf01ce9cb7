"""The ground map's layers as grid_map_msgs/GridMap and the learned speed as Nav2's speed filter
(nav2_msgs/CostmapFilterInfo and its OccupancyGrid mask), written to a ROS 2 bag (MCAP) and a
ROS 1 bag through rosbags and read back: the layers cell for cell in grid_map's layout, the
filter's values as Nav2 decodes them, each connection with its type's RIHS01 hash."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from terrapref.interop.ros_messages import (  # noqa: E402
    SPEED_ABSOLUTE,
    SPEED_PERCENT,
    grid_map,
    grid_map_layer,
    header,
    occupancy_grid,
    speed_filter,
    typestore,
)

ORIGIN, RES = (10.0, -4.0), 0.1
GRID_MAP_MD5 = "95681e052b1f73bf87b7eb984382b401"  # grid_map_msgs/GridMap's md5sum as ROS 1's grid_map package gives it


def _layers() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    elevation = rng.normal(0.0, 0.3, (5, 7)).astype(np.float32)
    elevation[2, 3] = np.nan  # unknown
    speed = np.full((5, 7), 1.2, dtype=np.float32)
    speed[0, 0] = 0.4  # the corner at the least x and y
    return {"elevation": elevation, "speed": speed}


def test_a_grid_map_holds_its_layers_in_grid_maps_layout_and_reads_back_cell_for_cell() -> None:
    ts = typestore()
    msg = grid_map(ts, header(ts, 1.5, "odom"), _layers(), RES, ORIGIN)
    assert (msg.info.length_x, msg.info.length_y) == pytest.approx((0.7, 0.5))
    assert (msg.info.pose.position.x, msg.info.pose.position.y) == pytest.approx((10.35, -3.75))  # the centre
    speed = msg.data[1]
    assert [d.label for d in speed.layout.dim] == ["column_index", "row_index"]
    assert (speed.layout.dim[0].size, speed.layout.dim[1].size) == (5, 7)
    # grid_map's index (0, 0) is the cell of the largest x and y; stored column by column, the
    # cell of the least x and y comes last.
    assert speed.data[-1] == pytest.approx(0.4) and (speed.data[:-1] == np.float32(1.2)).all()
    for name, layer in _layers().items():
        np.testing.assert_array_equal(grid_map_layer(msg, name), layer)


@pytest.mark.parametrize("percent", [True, False])
def test_a_speed_filter_decodes_as_nav2_reads_it_to_the_learned_speed(percent: bool) -> None:
    ts = typestore()
    speed = np.array([[0.3, 1.0, np.nan], [2.0, 0.0, 1.55]])
    info, mask = speed_filter(ts, header(ts, 0.0, "odom"), speed, 2.0, "/terrapref/speed_mask", percent)
    assert info.type == (SPEED_PERCENT if percent else SPEED_ABSOLUTE) and info.filter_mask_topic == "/terrapref/speed_mask"
    assert mask.dtype == np.int8 and mask[0, 2] == 0  # unknown: no limit, as Nav2 reads 0 (-1 is an invalid cell to it)
    assert (mask[np.isfinite(speed)] >= 1).all()  # a learned speed, even 0 (lethal ground), is never "no limit" (0)
    limit = info.base + info.multiplier * mask.astype(float)
    as_mps = limit / 100.0 * 2.0 if percent else limit
    known = np.isfinite(speed) & (speed > 0)
    np.testing.assert_allclose(as_mps[known], speed[known], atol=0.5 * 2.0 / 100.0 + 1e-6)


def test_written_to_ros2_and_ros1_bags_each_reads_back_with_its_types_hash(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    ts = typestore()
    stamped = header(ts, 2.0, "odom")
    info, mask = speed_filter(ts, stamped, _layers()["speed"], 2.0, "/speed_mask")
    messages = {
        "/grid_map": ("grid_map_msgs/msg/GridMap", grid_map(ts, stamped, _layers(), RES, ORIGIN)),
        "/speed_filter_info": ("nav2_msgs/msg/CostmapFilterInfo", info),
        "/speed_mask": ("nav_msgs/msg/OccupancyGrid", occupancy_grid(ts, stamped, mask, RES, ORIGIN)),
    }
    with Writer(tmp_path / "ros2", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, (msgtype, msg) in messages.items():
            writer.write(writer.add_connection(topic, msgtype, typestore=ts), 1, ts.serialize_cdr(msg, msgtype))
    with Reader(tmp_path / "ros2") as reader:
        for conn, _, raw in reader.messages():
            msgtype = messages[conn.topic][0]
            assert conn.msgtype == msgtype and conn.digest == ts.hash_rihs01(msgtype) and conn.digest.startswith("RIHS01_")
            back = ts.deserialize_cdr(raw, msgtype)
            if msgtype.endswith("GridMap"):
                np.testing.assert_array_equal(grid_map_layer(back, "elevation"), _layers()["elevation"])
            elif msgtype.endswith("CostmapFilterInfo"):
                assert (back.type, back.filter_mask_topic, back.multiplier) == (SPEED_PERCENT, "/speed_mask", 1.0)
            else:
                np.testing.assert_array_equal(back.data.reshape(mask.shape), mask)
    ts1 = typestore(ros1=True)
    stamped1 = header(ts1, 2.0, "odom", ros1=True)
    with Writer1(tmp_path / "ros1.bag") as writer:
        conn = writer.add_connection("/grid_map", "grid_map_msgs/msg/GridMap", typestore=ts1)
        writer.write(conn, 1, ts1.serialize_ros1(grid_map(ts1, stamped1, _layers(), RES, ORIGIN, ros1=True), conn.msgtype))
    with Reader1(tmp_path / "ros1.bag") as reader:
        (conn, _, raw), *_ = list(reader.messages())
        back = ts1.deserialize_ros1(raw, conn.msgtype)
        assert back.info.header.frame_id == "odom"
        assert conn.digest == GRID_MAP_MD5 == ts1.gendefhash("grid_map_msgs/msg/GridMap", {})[1]
        np.testing.assert_array_equal(grid_map_layer(back, "speed"), _layers()["speed"])


def test_a_files_maps_are_offered_transient_local_and_the_filters_info_written_once(tmp_path: Path) -> None:
    """Nav2's speed filter subscribes to its info and mask transient-local, as costmaps subscribe
    to a map: a file offers every map topic so (latched in ROS 1), and writes the filter's info
    only when it changes (Nav2 takes each info as a new filter and subscribes again)."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer

    from terrapref.interop.mcap_export import COSTMAP_TOPICS, TOPICS
    from terrapref.interop.ros_messages import add_topics

    ts = typestore()
    with Writer(tmp_path / "ros2", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        topics = add_topics(writer, ts, TOPICS)
        stamped = header(ts, 0.0, "odom")
        for t in range(3):  # three costmaps a second apart, the filter's info the same, then another
            info, _ = speed_filter(ts, stamped, _layers()["speed"], 2.0 if t < 2 else 1.5, "/terrapref/speed_mask", percent=t < 2)
            topics.write_changed("speed_filter_info", t, info, (info.type, info.base, info.multiplier))
    with AnyReader([tmp_path / "ros2"]) as reader:
        latched = {
            c.topic for c in reader.connections if [q.durability for q in c.ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        }
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert latched == {topic for topic, _ in COSTMAP_TOPICS.values()} | {"/tf_static"}
    assert counts["/terrapref/speed_filter_info"] == 2
    ts1 = typestore(ros1=True)
    with Writer1(tmp_path / "ros1.bag") as writer:
        add_topics(
            writer,
            ts1,
            {role: (topic, msgtype) for role, (topic, msgtype) in TOPICS.items() if role in ("costmap", "grid_map", "tf")},
            ros1=True,
        )
    with AnyReader([tmp_path / "ros1.bag"]) as reader:
        assert {c.topic: c.ext.latching for c in reader.connections} == {"/terrapref/costmap": 1, "/terrapref/grid_map": 1, "/tf": None}
