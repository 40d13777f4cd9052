#!/usr/bin/env python3
"""A Python goal client for wlnavd over iceoryx2 shared memory.

Sends one goal, follows the telemetry and exits 0 when the goal ends `succeeded`
(1 on any other outcome, 2 on a usage or connection error).

    python3 -m venv .venv && .venv/bin/pip install -r examples/requirements.txt
    wlnavd --sim --prefix demo &
    .venv/bin/python examples/python_client.py --prefix demo

The payloads are the `#[repr(C)]` structs of `shm-ipc/src/msg.rs` (wire v2): the type
names, sizes and alignments below must equal the Rust ones, which iceoryx2 checks when the
service is opened; the offsets are the ones `msg.rs` asserts at compile time. Telemetry is
read as bytes at those offsets (only the fields this client shows).

Its timeouts are multiplied by WLNAV_TIMING_SCALE when set (a slower CPU, e.g. an arm64
daemon under qemu in scripts/cross-check.sh; the rule of tests/timing_scale.rs).
"""

import argparse
import ctypes
import math
import os
import struct
import sys
import time

import iceoryx2 as iox2

API_VERSION = "v2"
MAX_OBSTACLES = 8
REASON_TEXT_CAPACITY = 128
GOAL_KIND_SET_GOAL = 1
EVENT_GOAL_REQUEST = 1  # shm_ipc::event_ids::GOAL_REQUEST
OUTCOMES = {0: "none", 1: "succeeded", 2: "cancelled", 3: "preempted", 4: "aborted"}


class Pose2(ctypes.Structure):
    _fields_ = [("x", ctypes.c_double), ("y", ctypes.c_double), ("heading", ctypes.c_double)]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::Pose2"


class Obstacle(ctypes.Structure):
    _fields_ = [("x", ctypes.c_double), ("y", ctypes.c_double), ("r", ctypes.c_double)]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::Obstacle"


class GoalRequest(ctypes.Structure):
    _fields_ = [
        ("request_id", ctypes.c_uint64),
        ("kind", ctypes.c_uint32),
        ("obstacle_count", ctypes.c_uint32),
        ("goal", Pose2),
        ("obstacles", Obstacle * MAX_OBSTACLES),
    ]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::GoalRequest"


class GoalReply(ctypes.Structure):
    _fields_ = [
        ("request_id", ctypes.c_uint64),
        ("accepted", ctypes.c_uint32),
        ("reason_code", ctypes.c_uint32),
        ("reason_len", ctypes.c_uint32),
        ("_reserved", ctypes.c_uint32),
        ("reason", ctypes.c_uint8 * REASON_TEXT_CAPACITY),
    ]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::GoalReply"

    def reason_text(self) -> str:
        return bytes(self.reason[: min(self.reason_len, REASON_TEXT_CAPACITY)]).decode("utf-8", "replace")


class Telemetry(ctypes.Structure):
    """2 816 bytes, 8-byte aligned; read with `field()` at msg.rs's offsets."""

    _fields_ = [("raw", ctypes.c_uint64 * (2816 // 8))]

    @staticmethod
    def type_name() -> str:
        return "wlnav::v2::Telemetry"

    def field(self, fmt: str, offset: int):
        return struct.unpack_from(fmt, bytes(self), offset)[0]


# The sizes msg.rs asserts: a mismatch would only show as "incompatible type" on open.
for t, size in [(Pose2, 24), (Obstacle, 24), (GoalRequest, 232), (GoalReply, 152), (Telemetry, 2816)]:
    assert ctypes.sizeof(t) == size and ctypes.alignment(t) == 8, t


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
    parser.add_argument("--goal", default="5,1,0.5", help="x,y,heading [m, m, rad] (default 5,1,0.5)")
    args = parser.parse_args()
    try:
        x, y, heading = (float(v) for v in args.goal.split(","))
    except ValueError:
        print(f"--goal must be x,y,heading (got {args.goal!r})", file=sys.stderr)
        return 2

    scale = timing_scale()
    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    goal_name = iox2.ServiceName.new(f"{args.prefix}/{API_VERSION}/goal")
    telemetry_name = iox2.ServiceName.new(f"{args.prefix}/{API_VERSION}/telemetry")

    # The daemon creates the services; wait for it to come up.
    deadline = time.monotonic() + 20.0 * scale
    while True:
        try:
            goal_service = node.service_builder(goal_name).request_response(GoalRequest, GoalReply).open()
            goal_event = node.service_builder(goal_name).event().open()
            telemetry_service = node.service_builder(telemetry_name).publish_subscribe(Telemetry).open()
            break
        except Exception as e:  # the iceoryx2 open errors
            if time.monotonic() > deadline:
                print(f"no wlnavd on prefix {args.prefix!r}: {e}", file=sys.stderr)
                return 2
            time.sleep(0.2)
    client = goal_service.client_builder().create()
    notifier = goal_event.notifier_builder().create()
    telemetry = telemetry_service.subscriber_builder().create()

    # Goals are refused until the daemon has its first pose and machine state.
    request_id = int(time.time() * 1e6)
    deadline = time.monotonic() + 20.0 * scale
    while True:
        request = GoalRequest(request_id=request_id, kind=GOAL_KIND_SET_GOAL, obstacle_count=0,
                              goal=Pose2(x, y, heading))
        pending = client.send_copy(request)
        notifier.notify_with_custom_event_id(iox2.EventId.new(EVENT_GOAL_REQUEST))
        reply = None
        until = time.monotonic() + 2.0 * scale
        while reply is None and time.monotonic() < until:
            response = pending.receive()
            if response is not None:
                reply = response.payload().contents
            else:
                time.sleep(0.01)
        if reply is not None and reply.accepted:
            break
        if time.monotonic() > deadline:
            why = reply.reason_text() if reply is not None else "no reply"
            print(f"goal rejected: {why}", file=sys.stderr)
            return 1
        request_id += 1
        time.sleep(0.2)
    print(f"goal {request_id} accepted: ({x}, {y}, {heading})")

    # Telemetry, every tick; the outcome comes once, with the goal's request id.
    deadline = time.monotonic() + 90.0 * scale
    last_print = 0.0
    while time.monotonic() < deadline:
        sample = telemetry.receive()
        if sample is None:
            time.sleep(0.02)
            continue
        t = sample.payload().contents
        if t.field("<Q", 2136) == request_id:  # outcome_request_id
            outcome = OUTCOMES.get(t.field("<I", 2144), "unknown")
            n = min(t.field("<I", 2156), REASON_TEXT_CAPACITY)
            text = bytes(t)[2160:2160 + n].decode("utf-8", "replace")
            print(f"goal {request_id}: {outcome} ({text})")
            return 0 if outcome == "succeeded" else 1
        if time.monotonic() - last_print > 1.0:
            last_print = time.monotonic()
            xf, yf, _, _, _, vf = struct.unpack_from("<6d", bytes(t), 80)  # state
            print(f"at ({xf:.2f}, {yf:.2f}) {vf:.2f} m/s, error {t.field('<d', 64):.2f} m")
    print(f"no outcome within {90.0 * scale:g} s", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
