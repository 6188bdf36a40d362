#!/usr/bin/env bash
# Installs the ROS 2 Python wheels the ROS 2 driver tests talk to (rclpy's CDR
# serializer, the message packages, an rmw, and zenoh's Python binding) into
# .venv-ros2 at the repository root. Idempotent: does nothing when they import.
set -euo pipefail
cd "$(dirname "$0")/../.."
VENV=.venv-ros2
PY=${PYTHON:-python3}
if [ -x "$VENV/bin/python" ] && "$VENV/bin/python" -c \
    "import rclpy.serialization, sensor_msgs.msg, nav_msgs.msg, diagnostic_msgs.msg, zenoh" 2>/dev/null; then
    exit 0
fi
"$PY" -m venv "$VENV"
"$VENV/bin/pip" install --quiet --disable-pip-version-check \
    ros-rclpy ros-sensor-msgs ros-nav-msgs ros-geometry-msgs ros-std-msgs ros-diagnostic-msgs \
    ros-rmw-fastrtps-cpp "eclipse-zenoh==1.10.2"
