"""Sample robot logs to try `terrapref import`, `train` and `replay` without a robot.

Writes drives of the synthetic driver as a ROS 2 MCAP bag (folder drive_mcap, as `ros2 bag record`
writes it), a ROS 1 bag (drive.bag) and a held-out ROS 2 sqlite3 bag (folder heldout_sqlite3),
with what real logs contain (RELLIS-3D label ids, stamp jitter and transport delay, odometry
from the robot's own origin, commands only on change, dropped and out-of-order images, a gap in
the odometry, an unrelated topic, /tf_static), and the robot file that reads them.

    .venv/bin/python examples/robot_logs.py --out logs [--scenario teach_course] [--heldout test_course]

The logs are written by the tests' generator (tests/synthetic_bag.py), with rosbags: it needs a
clone of the repository and terrapref's robot extra (scripts/setup.sh installs every extra).
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the generator lives beside the tests that use it
from synthetic_bag import write_robot, write_synthetic_bag  # noqa: E402

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", type=Path, required=True, help="folder to write the logs into")
parser.add_argument("--scenario", default="teach_course", help="course of the training drive")
parser.add_argument("--heldout", default="test_course", help="course of the held-out drive (for replay)")
parser.add_argument("--seed", type=int, default=0)
args = parser.parse_args()

args.out.mkdir(parents=True, exist_ok=True)
write_robot(args.out / "robot.yaml")  # with the label map it names beside it
for storage, name, scenario, seed in (
    ("mcap", "drive_mcap", args.scenario, args.seed),
    ("rosbag1", "drive.bag", args.scenario, args.seed),
    ("sqlite3", "heldout_sqlite3", args.heldout, args.seed + 1),
):
    path = args.out / name
    if path.exists():
        print(f"{path} exists; skipped")
        continue
    write_synthetic_bag(path, storage, scenario=scenario, seed=seed, encoding="png")
    print(f"wrote {path} ({storage}, {scenario})")
print(f"wrote {args.out / 'robot.yaml'} and the label map it names")
