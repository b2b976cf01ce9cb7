#!/usr/bin/env bash
# ROS 1 from Debian's own packages, for `terrapref ros1` and its test against a real roscore.
# Installed where apt can (as root, Debian 12); elsewhere the node's test is skipped with the reason.
set -uo pipefail
PACKAGES="ros-core python3-rospy python3-geometry-msgs python3-sensor-msgs python3-nav-msgs python3-visualization-msgs python3-std-msgs"
if command -v roscore > /dev/null && dpkg -s $PACKAGES > /dev/null 2>&1; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get > /dev/null; then
  echo "note: ROS 1 not installed (needs root and apt: apt-get install $PACKAGES); its test will be skipped"
  exit 0
fi
echo "installing ROS 1 from Debian's packages ($PACKAGES) ..."
if ! DEBIAN_FRONTEND=noninteractive apt-get install -y -q $PACKAGES > /tmp/terrapref-ros1-apt.log 2>&1; then
  (apt-get update -q > /dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -q $PACKAGES > /tmp/terrapref-ros1-apt.log 2>&1) \
    || echo "note: installing ROS 1 failed (see /tmp/terrapref-ros1-apt.log); its test will be skipped"
fi
exit 0
