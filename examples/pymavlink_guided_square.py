#!/usr/bin/env python3
"""ArduCopter in GUIDED mode through pymavlink: arm, take off, fly a 5 m square, land.

The ArduPilot acceptance flight of autopilot-in-the-loop (docs/autopilot-in-the-loop.md):
a real ArduCopter SITL flying ft-sitl's physics through `ft-sitl bridge ardupilot`.
Waits for each corner (LOCAL_POSITION_NED within 0.3 m, slower than 0.3 m/s) instead of
sleeping. Exits 0 only if every corner and the landing succeeded.

    python examples/pymavlink_guided_square.py [tcp:127.0.0.1:5760] [--side 5] [--alt 3]
"""

import argparse
import math
import sys
import time

from pymavlink import mavutil

TOLERANCE_M = 0.3
LEG_TIMEOUT_S = 120.0


def wait(m, kinds, pred, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = m.recv_match(type=kinds, blocking=True, timeout=1.0)
        if msg is None:
            continue
        if msg.get_type() == "STATUSTEXT":
            print(f"  autopilot: {msg.text}")
            continue
        if pred(msg):
            return msg
    raise TimeoutError(what)


def command(m, cmd, *params):
    p = list(params) + [0.0] * (7 - len(params))
    m.mav.command_long_send(m.target_system, m.target_component, cmd, 0, *p)
    ack = wait(m, ["COMMAND_ACK", "STATUSTEXT"], lambda a: a.command == cmd, 10.0,
               f"ack of command {cmd}")
    return ack.result


def main(url: str, side: float, alt: float) -> int:
    m = mavutil.mavlink_connection(url, source_system=255)
    m.wait_heartbeat(timeout=60)
    print(f"connected: system {m.target_system}")
    m.mav.request_data_stream_send(m.target_system, m.target_component,
                                   mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    m.set_mode("GUIDED")
    # ArduCopter arms once its EKF has settled (about 30-60 s after boot in SITL)
    t0 = time.monotonic()
    while True:
        res = command(m, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        if res == mavutil.mavlink.MAV_RESULT_ACCEPTED:
            break
        if time.monotonic() - t0 > 180.0:
            print("could not arm within 180 s")
            return 1
        time.sleep(2.0)
    print(f"armed after {time.monotonic() - t0:.0f} s")
    res = command(m, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt)
    if res != mavutil.mavlink.MAV_RESULT_ACCEPTED:
        print(f"take-off refused (MAV_RESULT {res})")
        return 1
    wait(m, ["LOCAL_POSITION_NED", "STATUSTEXT"], lambda p: -p.z > alt - TOLERANCE_M,
         LEG_TIMEOUT_S, "the take-off altitude")
    print(f"took off to {alt:g} m")
    ok = True
    legs = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side), (0.0, 0.0)]
    mask = 0b0000111111111000  # position only
    for north, east in legs:
        end = time.monotonic() + LEG_TIMEOUT_S
        reached = None
        while time.monotonic() < end and reached is None:
            m.mav.set_position_target_local_ned_send(
                0, m.target_system, m.target_component, mavutil.mavlink.MAV_FRAME_LOCAL_NED,
                mask, north, east, -alt, 0, 0, 0, 0, 0, 0, 0, 0)
            msg = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1.0)
            if msg is not None and math.dist((msg.x, msg.y, msg.z), (north, east, -alt)) \
                    < TOLERANCE_M and math.hypot(msg.vx, msg.vy) < 0.3:
                reached = msg
        if reached is None:
            print(f"corner N {north} E {east}: NOT reached within {LEG_TIMEOUT_S:g} s")
            ok = False
        else:
            print(f"corner N {north:4.1f} E {east:4.1f} up {alt:.1f}: reached "
                  f"({reached.x:+.2f}, {reached.y:+.2f}, {reached.z:+.2f})")
    m.set_mode("LAND")
    try:
        wait(m, ["HEARTBEAT", "STATUSTEXT"],
             lambda h: h.get_srcSystem() == m.target_system and h.type != 6
             and not h.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 180.0,
             "disarm after landing")
        print("landed and disarmed")
    except TimeoutError:
        print("did not land and disarm")
        ok = False
    print("SQUARE OK" if ok else "SQUARE FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("url", nargs="?", default="tcp:127.0.0.1:5760")
    ap.add_argument("--side", type=float, default=5.0)
    ap.add_argument("--alt", type=float, default=3.0)
    a = ap.parse_args()
    sys.exit(main(a.url, a.side, a.alt))
