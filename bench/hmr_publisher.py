#!/usr/bin/env python3
"""The HMR side of ``bench/node_latency.py --publishers split``: joints from a process of their own.

    python bench/hmr_publisher.py JOINTS.npy CAMERA_FRAME

In a deployment the HMR model and the SLAM system are different processes: the joints do not
share a DDS participant (nor Fast DDS's per-participant shared-memory segment) with the map and
the poses. This process publishes ``/hmr/joints`` (PoseArray, reliable, depth 10, as the
benchmark's own publisher) from ``JOINTS.npy`` ((F, 24, 3) float, metres, camera optical frame).

Protocol on stdin/stdout (one line each, JSON):
- prints ``{"ready": true}`` once its publisher matches a subscription (the node's);
- reads ``{"start_perf_ns": ..., "start_stamp_ns": ..., "period_ns": ..., "delay_ns": ...,
  "frames": ...}``: frame i is stamped ``start_stamp_ns + i * period_ns`` (the image's stamp, as
  the SLAM side stamps its pose) and published at ``start_perf_ns + i * period_ns + delay_ns``
  on ``time.perf_counter_ns`` (CLOCK_MONOTONIC: the same clock in every process on Linux);
- prints ``{"sent": [[stamp_ns, perf_counter_ns, time_ns], ...]}``, the instants just before
  each publish, and exits.

The parent sets the DDS environment (localhost discovery, its domain, any profile); this process
inherits it.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402

from msg_adapters import joints_to_pose_array, rclpy_types  # noqa: E402

READY_TIMEOUT_S = 30.0


def main(argv: list[str]) -> int:
    joints_cam = np.load(argv[1])
    camera_frame = argv[2]
    types = rclpy_types()
    rclpy.init()
    node = rclpy.create_node('hac_latency_hmr')
    publisher = node.create_publisher(types.get('geometry_msgs/msg/PoseArray'), '/hmr/joints',
                                      QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + READY_TIMEOUT_S
    while publisher.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            print(json.dumps({'ready': False}), flush=True)
            return 1
        time.sleep(0.01)
    messages = [joints_to_pose_array(np.asarray(j), 0, camera_frame, types) for j in joints_cam]
    print(json.dumps({'ready': True}), flush=True)
    plan = json.loads(sys.stdin.readline())
    sent = []
    for i in range(min(plan['frames'], len(messages))):
        stamp = plan['start_stamp_ns'] + i * plan['period_ns']
        due = plan['start_perf_ns'] + i * plan['period_ns'] + plan['delay_ns']
        delay = (due - time.perf_counter_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)
        msg = messages[i]
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        sent.append((stamp, time.perf_counter_ns(), time.time_ns()))
        publisher.publish(msg)
    print(json.dumps({'sent': sent}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
