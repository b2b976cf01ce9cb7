"""Realistic robot logs made from the simulator: a drive by the synthetic driver, written as a ROS 1
bag, a ROS 2 sqlite3 bag or a ROS 2 MCAP bag, with what real logs contain.

The quirks (``quirks=True``): label images in RELLIS-3D ids (plus a few ids no map lists), header
stamps from an epoch-like clock with jitter and a transport delay, odometry at 30 Hz in a frame
that starts at the robot, commands published only when they change, the path published once,
an unrelated topic, dropped images, pairs of images whose stamps arrive out of order, and a
one-second gap in the odometry. Used by the tests and the import benchmark; not a user command.
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Literal

import numpy as np
from PIL import Image as PILImage

from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.session import Disturber
from terrapref.recipes import DEFAULT_RECIPE, RECIPES
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import default_classes

Storage = Literal["rosbag1", "sqlite3", "mcap"]
TOPICS = {"segmentation": "/robot/seg/labels", "camera_info": "/robot/camera/camera_info", "odometry": "/robot/odom",
          "command": "/robot/cmd_vel", "path": "/route/plan"}
EPOCH_S = 1_700_000_000
RELLIS = {"grass": 3, "mud": 33, "rock": 34, "water": 6, "non_traversable": 19}  # and unknown (sky) -> 7
UNLISTED_ID = 50  # an id the rellis3d map does not list
COLORS = {3: (0, 102, 0), 33: (255, 128, 0), 34: (170, 170, 170), 6: (0, 128, 255), 19: (204, 153, 255), 7: (135, 206, 235)}  # for rgb8 logs


def colour_label_map() -> str:
    """A terrapref-labels/1 file with rellis3d's ids and :data:`COLORS` as its colour table."""
    names = {0: "unknown", 3: "grass", 33: "mud", 34: "rock", 6: "water", 19: "non_traversable", 7: "unknown"}
    ids = "\n".join(f"  {k}: {v}" for k, v in names.items())
    colors = "\n".join(f"  {k}: [{r}, {g}, {b}]" for k, (r, g, b) in COLORS.items())
    return f"format: terrapref-labels/1\nname: colour_rellis\nids:\n{ids}\ncolors:\n{colors}\n"


def robot_yaml(labels: str = "rellis3d", path_topic: bool = True) -> str:
    """The robot file that matches :func:`write_synthetic_bag`'s topics."""
    topics = "\n".join(f"  {k}: {v}" for k, v in TOPICS.items() if path_topic or k != "path")
    return f"format: terrapref-robot/1\ntopics:\n{topics}\ncamera:\n  height_m: 1.0\n  pitch_deg: 30.0\nlabels: {labels}\n"


def write_synthetic_bag(out: str | Path, storage: Storage = "mcap", scenario: str = "demo_course", seed: int = 0,
                        profile: tuple[str, ...] | None = None, encoding: Literal["mono8", "mono16", "png", "rgb8"] = "mono8",
                        quirks: bool = True, max_seconds: float | None = None, repeat_images: int = 1) -> Path:
    """Drive ``scenario`` with the synthetic driver and write the log; returns the bag's path.

    ``repeat_images`` > 1 publishes each frame that many times per 0.1 s (a faster camera), to
    make large logs for benchmarks.
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    out = Path(out)
    ros1 = storage == "rosbag1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.fielddefs:  # not in rosbags' ROS 1 store: registered from its definition
        from rosbags.typesys import get_types_from_msg

        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    classes = default_classes()
    to_ids = np.full(256, 7, np.uint16)
    for name, rid in RELLIS.items():
        to_ids[classes.id_of(name)] = rid

    sc = resolve_scenario(scenario)
    sim = Simulation(sc)
    rng = np.random.default_rng(seed)
    driver = ExpertDriver(ExpertConfig.styled("default", profile), world=sim.world)
    protocol = RECIPES[DEFAULT_RECIPE].disturbance
    sx, sy, syaw = sc.start if quirks else (0.0, 0.0, 0.0)
    c, s = math.cos(syaw), math.sin(syaw)

    def to_odom(x: float, y: float, yaw: float) -> tuple[float, float, float]:  # the frame that starts at the robot
        dx, dy = x - sx, y - sy
        return c * dx + s * dy, -s * dx + c * dy, yaw - syaw

    def time(t_s: float):
        ns = int(round((EPOCH_S + t_s) * 1e9))
        return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(t_s: float, frame: str):
        H = T["std_msgs/msg/Header"]
        return H(seq=0, stamp=time(t_s), frame_id=frame) if ros1 else H(stamp=time(t_s), frame_id=frame)

    def quat(yaw: float):
        return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def point(x: float, y: float):
        return T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0)

    def vec(x: float = 0.0, z: float = 0.0):
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=0.0, z=float(z))

    cam = sim.camera.config
    fx, fy, cx, cy = sim.camera.config.intrinsics
    h, w = cam.height_px, cam.width_px

    def camera_info(t_s: float):
        kw = dict(header=header(t_s, "camera_optical"), height=h, width=w, distortion_model="plumb_bob",
                  binning_x=0, binning_y=0, roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        arrays = {"d": np.zeros(5), "k": np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1.0]), "r": np.eye(3).ravel(), "p": np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1.0, 0])}
        kw.update({(k.upper() if ros1 else k): v for k, v in arrays.items()})
        return T["sensor_msgs/msg/CameraInfo"](**kw)

    def image(t_s: float, ids: np.ndarray):
        if encoding == "png":
            buf = io.BytesIO()
            PILImage.fromarray(ids.astype(np.uint8)).save(buf, format="PNG", compress_level=1)
            return "sensor_msgs/msg/CompressedImage", T["sensor_msgs/msg/CompressedImage"](header=header(t_s, "camera_optical"), format="mono8; png compressed", data=np.frombuffer(buf.getvalue(), np.uint8))
        if encoding == "rgb8":  # a colour segmentation: the RELLIS ids through COLORS
            rgb = np.zeros((*ids.shape, 3), np.uint8)
            for rid, colour in COLORS.items():
                rgb[ids == rid] = colour
            return "sensor_msgs/msg/Image", T["sensor_msgs/msg/Image"](header=header(t_s, "camera_optical"), height=h, width=w, encoding="rgb8", is_bigendian=0,
                                                                   step=3 * w, data=rgb.reshape(-1))
        data = ids.astype("<u2" if encoding == "mono16" else np.uint8)
        return "sensor_msgs/msg/Image", T["sensor_msgs/msg/Image"](header=header(t_s, "camera_optical"), height=h, width=w, encoding=encoding, is_bigendian=0,
                                                               step=w * data.itemsize, data=np.frombuffer(data.tobytes(), np.uint8))

    if ros1:
        writer = Writer1(out)
    else:
        writer = Writer2(out, version=9, storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3)
    with writer:
        seg_type = "sensor_msgs/msg/CompressedImage" if encoding == "png" else "sensor_msgs/msg/Image"
        conns = {
            "segmentation": writer.add_connection(TOPICS["segmentation"], seg_type, typestore=ts),
            "camera_info": writer.add_connection(TOPICS["camera_info"], "sensor_msgs/msg/CameraInfo", typestore=ts),
            "odometry": writer.add_connection(TOPICS["odometry"], "nav_msgs/msg/Odometry", typestore=ts),
            "command": writer.add_connection(TOPICS["command"], "geometry_msgs/msg/Twist", typestore=ts),
            "path": writer.add_connection(TOPICS["path"], "nav_msgs/msg/Path", typestore=ts),
            "other": writer.add_connection("/diagnostics/status", "std_msgs/msg/String", typestore=ts),
            "tf_static": writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts),
        }
        queue: list[tuple[float, str, object, str]] = []  # (bag time, role, message, type), flushed in bag-time order

        def put(bag_t: float, role: str, msg, msgtype: str) -> None:
            queue.append((bag_t, role, msg, msgtype))

        def flush(upto: float) -> None:
            queue.sort(key=lambda q: q[0])
            while queue and queue[0][0] <= upto:
                bag_t, role, msg, msgtype = queue.pop(0)
                data = ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)
                writer.write(conns[role], int(round((EPOCH_S + bag_t) * 1e9)), data)

        path_odom = [to_odom(x, y, 0.0)[:2] for x, y in sc.waypoints]
        put(0.0, "path", T["nav_msgs/msg/Path"](header=header(0.0, "odom"), poses=[
            T["geometry_msgs/msg/PoseStamped"](header=header(0.0, "odom"), pose=T["geometry_msgs/msg/Pose"](position=point(x, y), orientation=quat(0.0)))
            for x, y in path_odom]), "nav_msgs/msg/Path")
        # The camera's mounting as a robot publishes it: base_link -> camera_link (x forward,
        # pitched down) -> camera_optical (z forward), the frame the images are stamped in.
        def transform(parent: str, child: str, xyz: tuple[float, float, float], q: tuple[float, float, float, float]):
            Q = T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
            return T["geometry_msgs/msg/TransformStamped"](header=header(0.0, parent), child_frame_id=child,
                                                            transform=T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]), rotation=Q))
        p2 = math.radians(cam.pitch_deg) / 2
        put(0.0, "tf_static", T["tf2_msgs/msg/TFMessage"](transforms=[
            transform("base_link", "camera_link", (cam.mount_forward_m, 0.0, cam.mount_height_m), (0.0, math.sin(p2), 0.0, math.cos(p2))),
            transform("camera_link", "camera_optical", (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5))]), "tf2_msgs/msg/TFMessage")
        frame = sim.reset()
        driver.reset(sc, rng)  # then the pushes' stream, in the order `terrapref record` draws them: the same drive
        disturb = Disturber(protocol, np.random.default_rng(rng.integers(2**63)), 0.1) if protocol is not None else None
        jitter = np.random.default_rng(seed + 1)
        last_cmd = None
        swap_next = None
        gap = (8.0, 9.0) if quirks else (math.inf, math.inf)
        tick = 0
        while not sim.done and (max_seconds is None or frame.time_s < max_seconds):
            t = frame.time_s
            command = driver.act(frame)
            ids = to_ids[frame.image]
            if quirks:
                ids[:4, :40] = UNLISTED_ID
            stamp = t + (jitter.normal(0.0, 0.003) if quirks else 0.0)
            drop = quirks and frame.index % 50 == 49
            if not drop:
                for r in range(repeat_images):
                    st = stamp + r * 0.1 / repeat_images
                    if quirks and frame.index % 37 == 5 and r == 0:
                        swap_next = st  # this image's stamp goes to the next one: a pair out of order
                        continue
                    if swap_next is not None:
                        msgtype, msg = image(st, ids)
                        put(swap_next + 0.03, "segmentation", msg, msgtype)
                        msgtype, msg = image(swap_next, ids)
                        put(st + 0.03, "segmentation", msg, msgtype)
                        swap_next = None
                        continue
                    msgtype, msg = image(st, ids)
                    put(st + (0.03 if quirks else 0.0), "segmentation", msg, msgtype)
            if frame.index % 10 == 0:
                put(t + 0.001, "camera_info", camera_info(t), "sensor_msgs/msg/CameraInfo")
                put(t + 0.002, "other", T["std_msgs/msg/String"](data="ok"), "std_msgs/msg/String")
            if command != last_cmd or not quirks:
                put(t + 0.005, "command", T["geometry_msgs/msg/Twist"](linear=vec(x=command[0]), angular=vec(z=command[1])), "geometry_msgs/msg/Twist")
                last_cmd = command
            executed = disturb(command) if disturb is not None else command
            frame = sim.step(executed)
            for x, y, yaw in sim.trace[tick + 1:]:
                tick += 1
                t_odom = tick / 30.0
                if gap[0] <= t_odom < gap[1]:
                    continue
                ox, oy, oyaw = to_odom(x, y, yaw)
                pose = T["geometry_msgs/msg/PoseWithCovariance"](pose=T["geometry_msgs/msg/Pose"](position=point(ox, oy), orientation=quat(oyaw)), covariance=np.zeros(36))
                twist = T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](linear=vec(), angular=vec()), covariance=np.zeros(36))
                put(t_odom + (0.004 if quirks else 0.0), "odometry",
                    T["nav_msgs/msg/Odometry"](header=header(t_odom, "odom"), child_frame_id="base_link", pose=pose, twist=twist), "nav_msgs/msg/Odometry")
            flush(frame.time_s - 0.2)
        flush(math.inf)
    return out
