"""The ROS 2 node's throughput: how many frames a second it decides on, and how many frames of a
log played in real time (and faster) it keeps up with.

    .venv/bin/python benchmarks/bench_node.py [--model M.safetensors] [--rates 1,2,4] [--out DIR]

(a) core: the node's own work per frame (``PlannerNodeCore``: the PNG decoded, the odometry
    interpolated to the image's stamp, the planner's decision), fed a log's messages in this
    process, without DDS; the median per frame and its ratio to the reference.
(w) wire: a raw 640 x 480 label image (``mono8``) and depth image (``32FC1``), as a robot
    publishes them, serialised through the node's DDS types and read back; the medians.
(b) played: ``terrapref ros2`` in a process of its own, a log played to it by ``terrapref play``
    at each rate (1: the log's own pace); the frames it decided on out of those played. The node,
    the player and this process share the machine, as on a robot: no core pinning.

The log is ``demo_course`` driven by the synthetic driver and exported as ROS 2 MCAP; without
``--model`` the node drives with recipe teach trained for a few epochs on that drive (the default
decision: the offset rule at the speed rule's speed). Needs the ros2 and robot extras.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from reference import reference_ms  # benchmarks/reference.py (the script's folder is on sys.path)

LOOPBACK = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    '<Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>'
)  # the node and the player on this machine only
CLI = "import sys; from terrapref.cli import main; sys.exit(main())"


def _terrapref(*argv: str, env: dict | None = None) -> None:
    subprocess.run([sys.executable, "-c", CLI, *argv], check=True, env=env, stdout=subprocess.DEVNULL)


def prepare(work: Path, model: str | None) -> tuple[Path, Path, Path]:
    """The log (MCAP), its robot file and the model: made in ``work`` unless they are there."""
    rec, bag = work / "rec", work / "drive.mcap"
    if not rec.exists():
        _terrapref("record", "demo_course", "--out", str(rec), "--quiet", "--disturb", "0")
    if model is None:
        model = str(work / "teach.safetensors")
        if not Path(model).exists():
            _terrapref("train", str(rec), "--recipe", "teach", "--epochs", "5", "--out", model)
    if not bag.exists():
        _terrapref("export", str(rec), "--format", "mcap", "--out", str(bag))
    return bag, Path(f"{bag}.robot.yaml"), Path(model)


def core_times(bag: Path, robot_file: Path, model_file: Path) -> np.ndarray:
    """Each frame's time [s] in the node's core: its odometry and its image handed over, in the
    log's order, the calibration and the path first."""
    from rosbags.highlevel import AnyReader

    from terrapref.interop.node_core import PlannerNodeCore
    from terrapref.interop.robot import load_robot
    from terrapref.learning.model_file import load_model

    robot = load_robot(robot_file)
    core = PlannerNodeCore(load_model(model_file), robot)
    topics = robot.topics
    with AnyReader([bag]) as reader:
        messages = [(c.topic, c.msgtype, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    for topic, _, msg in messages:
        if topic == topics["camera_info"]:
            core.on_camera_info(msg)
        elif topic == topics.get("path"):
            core.on_path(msg)
        if core.ready:
            break
    times, start = [], None
    for topic, msgtype, msg in messages:
        if topic == topics["odometry"]:
            start = time.perf_counter() if start is None else start
            core.on_odometry(msg)
        elif topic == topics["segmentation"]:
            start = time.perf_counter() if start is None else start
            core.on_image(msgtype, msg, topic)
            times.append(time.perf_counter() - start)
            start = None
    if core.decided < 0.9 * len(times):
        raise SystemExit(f"the core decided on {core.decided} of {len(times)} frames: {core.skipped}")
    return np.array(times)


def played(bag: Path, robot: Path, model: Path, rate: float, domain: int) -> tuple[int, int]:
    """Frames the node decided on, and frames played, with ``bag`` played at ``rate``."""
    env = {**os.environ, "CYCLONEDDS_URI": LOOPBACK, "ROS_DOMAIN_ID": str(domain), "TERRAPREF_DEBUG": ""}
    node = subprocess.Popen(
        [sys.executable, "-c", CLI, "ros2", "--model", str(model), "--robot", str(robot), "--ros-args", "-p", "use_sim_time:=true"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        while "hears" not in (line := node.stderr.readline()):  # it has joined the domain and subscribed
            if not line and node.poll() is not None:
                raise SystemExit(f"the node ended: {node.stderr.read()[-2000:]}")
        play = subprocess.run(
            [sys.executable, "-c", CLI, "play", str(bag), "--robot", str(robot), "--rate", f"{rate:g}", "--delay", "1"],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
    finally:
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=60)
    decided = int(re.search(r"terrapref ros2: (\d+) frames decided on", out).group(1))
    frames = int(re.search(r"played (\d+) messages", play.stdout).group(1))
    return decided, frames


def wire_times(repeat: int = 50) -> dict[str, tuple[float, float]]:
    """Median seconds to serialise and to read back a raw label image and a depth image (640 x 480)."""
    from terrapref.interop import ros_messages as rm
    from terrapref.interop.dds import MessageTypes

    ts = rm.typestore()
    types = MessageTypes(ts)
    rng = np.random.default_rng(0)
    h = rm.header(ts, 1.0, "camera_optical")
    images = {
        "mono8": rng.integers(0, 20, (480, 640)).astype(np.uint8),
        "32FC1": rng.uniform(0.5, 20.0, (480, 640)).astype(np.float32),
    }
    out = {}
    for encoding, pixels in images.items():
        data = pixels.view(np.uint8).ravel()
        msg = ts.types["sensor_msgs/msg/Image"](
            header=h, height=480, width=640, encoding=encoding, is_bigendian=0, step=data.size // 480, data=data
        )
        cls, times = types.idl("sensor_msgs/msg/Image"), []
        for _ in range(repeat):
            t0 = time.perf_counter()
            wire = types.to_idl(msg, "sensor_msgs/msg/Image").serialize()
            t1 = time.perf_counter()
            cls.deserialize(wire)
            times.append((t1 - t0, time.perf_counter() - t1))
        out[encoding] = tuple(np.median(np.array(times), axis=0))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="the model the node drives with (default: recipe teach, a few epochs on the drive)")
    parser.add_argument("--rates", default="1,2,4", help="the rates the log is played at, over its own pace (default 1,2,4)")
    parser.add_argument("--domain", type=int, default=77, help="the DDS domain (ROS_DOMAIN_ID) of the node and the player")
    parser.add_argument("--out", type=Path, help="work folder, kept (default: a temporary one)")
    args = parser.parse_args()
    work = args.out or Path(tempfile.mkdtemp(prefix="terrapref-bench-node-"))
    work.mkdir(parents=True, exist_ok=True)
    bag, robot, model = prepare(work, args.model)
    ref = reference_ms()
    print(f"reference: naive NumPy render (reference.py)  {ref:.2f} ms")
    core_times(bag, robot, model)  # compiled loops and caches warmed
    t = core_times(bag, robot, model)
    print(
        f"node core, per frame (png decoded, odometry at its stamp, decision): median {np.median(t) * 1e3:.2f} ms "
        f"({1.0 / np.median(t):.0f} frames/s) over {len(t)} frames; median / reference {np.median(t) * 1e3 / ref:.3f}"
    )
    for encoding, (write_s, read_s) in wire_times().items():
        print(
            f"wire, a raw 640 x 480 {encoding} image through the node's DDS types: serialised {write_s * 1e3:.2f} ms, "
            f"read back {read_s * 1e3:.2f} ms; / reference {write_s * 1e3 / ref:.4f} and {read_s * 1e3 / ref:.4f}"
        )
    for rate in (float(r) for r in args.rates.split(",")):
        decided, messages = played(bag, robot, model, rate, args.domain)
        frames = len(t)
        print(f"terrapref play at {rate:g}x ({messages} messages, {frames} frames): the node decided on {decided} ({decided / frames:.0%})")


if __name__ == "__main__":
    main()
