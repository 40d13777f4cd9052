#!/usr/bin/env python3
"""A Python perception stand-in publishing live obstacles to wlnavd over iceoryx2.

A person walks across the machine's way at 1.4 m/s, 4 m ahead, from 5 m on its right to
5 m on its left, next to a parked truck (a convex polygon); one set every 100 ms. Exits 0
once the person has crossed and a set without the person went out (1 on an error, 2 on a
usage or connection error).

    python3 -m venv .venv && .venv/bin/pip install -r examples/requirements.txt
    wlnavd --sim --prefix demo --config examples/external-perception.toml &
    .venv/bin/python examples/python_obstacles.py --prefix demo

The payloads are the `#[repr(C)]` structs of `shm-ipc/src/msg.rs` (wire v2): the type
names, sizes and alignments below must equal the Rust ones, which iceoryx2 checks when the
service is opened; the offsets are the ones `msg.rs` asserts at compile time (checked
below with `ctypes`). The service `{prefix}/v2/obstacles` admits one publisher: while this
runs, no other process can publish obstacles on that prefix (and it cannot start while
another does). Stamps are CLOCK_MONOTONIC nanoseconds: `time.monotonic_ns()` on Linux.

Its timeouts are multiplied by WLNAV_TIMING_SCALE when set (the rule of
tests/timing_scale.rs).
"""

import argparse
import ctypes
import math
import os
import sys
import time

import iceoryx2 as iox2

API_VERSION = "v2"
MAX_LIVE_OBSTACLES = 128
MAX_POLYGON_VERTICES = 8
SHAPE_CIRCLE, SHAPE_POLYGON = 0, 1
CLASS_PERSON, CLASS_VEHICLE = 1, 2
EVENT_OBSTACLES = 7  # shm_ipc::event_ids::OBSTACLES
RATE_HZ = 10.0


class LiveObstacle(ctypes.Structure):
    _fields_ = [
        ("id", ctypes.c_uint32),
        ("shape", ctypes.c_uint32),
        ("class_", ctypes.c_uint32),  # `class` in Rust; a Python keyword
        ("vertex_count", ctypes.c_uint32),
        ("timestamp_ns", ctypes.c_uint64),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("radius", ctypes.c_double),
        ("vx", ctypes.c_double),
        ("vy", ctypes.c_double),
        ("vertices", (ctypes.c_double * 2) * MAX_POLYGON_VERTICES),
    ]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::LiveObstacle"


class LiveObstacleSet(ctypes.Structure):
    _fields_ = [
        ("timestamp_ns", ctypes.c_uint64),
        ("sequence", ctypes.c_uint32),
        ("count", ctypes.c_uint32),
        ("obstacles", LiveObstacle * MAX_LIVE_OBSTACLES),
    ]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::LiveObstacleSet"


# The sizes and offsets msg.rs asserts: a mismatch would only show as "incompatible type"
# on open, or as garbage the daemon rejects.
assert ctypes.sizeof(LiveObstacle) == 192 and ctypes.alignment(LiveObstacle) == 8
assert ctypes.sizeof(LiveObstacleSet) == 24592 and ctypes.alignment(LiveObstacleSet) == 8
for name, offset in [("id", 0), ("shape", 4), ("class_", 8), ("vertex_count", 12), ("timestamp_ns", 16),
                     ("x", 24), ("y", 32), ("radius", 40), ("vx", 48), ("vy", 56), ("vertices", 64)]:
    assert getattr(LiveObstacle, name).offset == offset, name
assert LiveObstacleSet.obstacles.offset == 16


def circle(obstacle_id, cls, x, y, radius, vx, vy, stamp):
    """A circle of physical `radius` [m] (the daemon adds the machine's outline)."""
    return LiveObstacle(id=obstacle_id, shape=SHAPE_CIRCLE, class_=cls, vertex_count=0, timestamp_ns=stamp,
                        x=x, y=y, radius=radius, vx=vx, vy=vy)


def polygon(obstacle_id, cls, vertices, vx, vy, stamp):
    """A convex polygon, 3 to 8 vertices in order around it (either winding)."""
    if not 3 <= len(vertices) <= MAX_POLYGON_VERTICES:
        raise ValueError(f"a polygon has 3 to {MAX_POLYGON_VERTICES} vertices, {len(vertices)} given")
    o = LiveObstacle(id=obstacle_id, shape=SHAPE_POLYGON, class_=cls, vertex_count=len(vertices),
                     timestamp_ns=stamp, vx=vx, vy=vy)
    for k, (x, y) in enumerate(vertices):
        o.vertices[k][0], o.vertices[k][1] = x, y
    return o


def timing_scale() -> float:
    """WLNAV_TIMING_SCALE, as tests/timing_scale.rs reads it: unset or empty is 1, and
    anything but a number >= 1 is an error."""
    s = os.environ.get("WLNAV_TIMING_SCALE", "").strip()
    if not s:
        return 1.0
    try:
        f = float(s)
    except ValueError:
        f = float("nan")
    if not (math.isfinite(f) and f >= 1.0):
        raise SystemExit(f"WLNAV_TIMING_SCALE={s!r}: must be a number >= 1 (the slow-down of this CPU)")
    return f


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prefix", default="wlnav", help="the daemon's ipc.prefix (default wlnav)")
    args = parser.parse_args()

    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(f"{args.prefix}/{API_VERSION}/obstacles")

    # The daemon creates the services (a peer only opens them); wait for it to come up.
    deadline = time.monotonic() + 20.0 * timing_scale()
    while True:
        try:
            service = node.service_builder(name).publish_subscribe(LiveObstacleSet).open()
            event = node.service_builder(name).event().open()
            break
        except Exception as e:  # the iceoryx2 open errors
            if time.monotonic() > deadline:
                print(f"no wlnavd on prefix {args.prefix!r}: {e}", file=sys.stderr)
                return 2
            time.sleep(0.2)
    try:
        publisher = service.publisher_builder().create()
    except Exception as e:  # one publisher per prefix: another perception holds it
        print(f"cannot publish on {args.prefix}/{API_VERSION}/obstacles (one publisher only): {e}",
              file=sys.stderr)
        return 2
    notifier = event.notifier_builder().create()

    speed, x, y_start, y_end = 1.4, 4.0, -5.0, 5.0
    crossing = (y_end - y_start) / speed
    truck = [(8.0, 2.0), (8.0, 4.5), (14.0, 4.5), (14.0, 2.0)]  # clockwise; parked
    start = time.monotonic()
    sequence = 0
    while True:
        t = time.monotonic() - start
        stamp = time.monotonic_ns()
        s = LiveObstacleSet(timestamp_ns=stamp, sequence=sequence, count=0)
        obstacles = [polygon(2, CLASS_VEHICLE, truck, 0.0, 0.0, stamp)]
        if t <= crossing:
            y = y_start + speed * t
            obstacles.append(circle(1, CLASS_PERSON, x, y, 0.3, 0.0, speed, stamp))
            if sequence % 10 == 0:
                print(f"t {t:4.1f} s: person at ({x:.1f}, {y:5.2f}) m")
        for i, o in enumerate(obstacles):
            s.obstacles[i] = o
        s.count = len(obstacles)
        publisher.send_copy(s)
        notifier.notify_with_custom_event_id(iox2.EventId.new(EVENT_OBSTACLES))
        sequence += 1
        if t > crossing:
            print(f"the person has crossed: {sequence} sets published, the last with the truck only")
            return 0
        # Absolute deadlines: a steady rate whatever a publish costs.
        time.sleep(max(0.0, start + sequence / RATE_HZ - time.monotonic()))


if __name__ == "__main__":
    sys.exit(main())
