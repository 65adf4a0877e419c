"""Moving obstacles over the wire (issue #24): `ft-sitl sitl` with movers publishes their
state on the MQTT bus and renders them in the bus's depth frames; a trial flown over
MAVLink ends as `mover_collision` when one is driven into the vehicle's path."""

import asyncio
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ft_sitl.bus.client import BusClient
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.transport.lockstep import run_trial_lockstep
from ft_sitl.transport.mavlink_trial import worker_bus

from ..bus.conftest import Mosquitto

pytestmark = pytest.mark.e2e  # (tests/lanes.py)
#: the columns that measure wall time (and when the row was written)
WALL_COLUMNS = ("wall_time_s", "planner_time_s", "finished_utc")

AGILE = "0.98kg-EGO Planner DIY"
FT_SITL = str(Path(sys.executable).parent / "ft-sitl")
INSTANCE = 67  # (ports of its own)
SPEED = 1.0  # the person's speed (m/s)


def _yard(directory: Path, movers_yaml: str) -> Path:
    """A 30 x 30 m yard, one box in a far corner (out of the camera's sight), start
    (15, 5, 1.5) facing the goal (15, 25, 1.5): north."""
    directory.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(bounds=[[1, 27, 0], [3, 29, 3]]).export(directory / "yard.ply")
    spec = directory / "yard.yaml"
    spec.write_text("name: yard\nmesh: yard.ply\nstart: [15.0, 5.0, 1.5]\n"
                    "goal: [15.0, 25.0, 1.5]\nbounds_min: [0, 0, 0]\nbounds_max: [30, 30, 5]\n"
                    "movers:\n" + movers_yaml)
    return spec


def test_sitl_publishes_movers_and_its_depth_frames_see_them_move(tmp_path):
    """A person walks east along y = 9 from x = 10 at 1 m/s, 4 m ahead of the vehicle on
    its takeoff spot (15, 5), across its camera's view. The bus carries the person's state
    (where the path says it is at each sample's time) and the depth frames hold its surface
    where it is at each frame's time: it moves between frames."""
    spec = _yard(tmp_path, "  - {shape: person, radius_m: 0.4, height_m: 1.8, "
                           f"points: [[10, 9], [20, 9]], speed_m_s: {SPEED}}}\n")
    broker = Mosquitto(tmp_path / "mq").start()
    sitl = subprocess.Popen([FT_SITL, "sitl", "--scenario", str(spec), "--instance",
                             str(INSTANCE), "--speed-factor", "1", "--mqtt", broker.url,
                             "--duration", "400"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    async def listen():
        states, frames = [], []
        async with BusClient(broker.url, str(INSTANCE), kinds=("movers", "depth")) as bus:
            async def ask():
                while True:
                    await bus.request_config(depth=True)
                    await asyncio.sleep(1.0)

            asker = asyncio.create_task(ask())
            try:
                # the first frame: after the start-up (long when numba compiles afresh)
                async with asyncio.timeout(300):
                    while (msg := await bus.receive()).kind != "depth":
                        states.append(msg.data)
                async with asyncio.timeout(60):
                    while True:  # until frames 1.5 s apart, both with the person in sight
                        msg = await bus.receive()
                        if msg.kind == "movers":
                            states.append(msg.data)
                        elif 2.5 <= msg.data.t <= 7.5:  # (it crosses the view in 2..8 s)
                            frames.append(msg.data.to_depth_frame())
                            if frames[-1].t_us - frames[0].t_us >= 1_500_000:
                                return states, frames
            finally:
                asker.cancel()

    try:
        states, frames = asyncio.run(listen())
    except TimeoutError:
        sitl.terminate()
        raise AssertionError("no depth frames 1.5 s apart with the person in sight: "
                             + "".join(sitl.communicate(timeout=30))[-3000:]) from None
    finally:
        if sitl.poll() is None:
            sitl.terminate()
        out, err = sitl.communicate(timeout=30)
        broker.kill()
    assert ("movers: 1 (1 x person), moving from simulated time 0; their state on the bus "
            "(topic ft-sitl/v1/<vehicle>/movers) and as ADSB_VEHICLE") in out, out + err
    # the bus: the person where its path puts it, at every sample's simulated time
    assert len(states) > 20
    for s in states:
        (m,) = s.movers
        assert (m.name, m.shape, m.radius_m, m.height_m) == ("person 1", "person", 0.4, 1.8)
        np.testing.assert_allclose(m.p_world_m, [10.0 + SPEED * s.t, 9.0, 0.9], atol=2e-4)
        assert m.heading_rad == 0.0
        assert m.v_world_m_s == ((SPEED, 0.0, 0.0) if s.time_usec else (0.0, 0.0, 0.0))
    assert states[-1].time_usec > states[0].time_usec
    # the depth frames: the only thing in sight is the person's near side, facing the camera
    xs = []
    for f in (frames[0], frames[-1]):
        x_c = 10.0 + SPEED * f.t_us * 1e-6  # its centre at the frame's time
        p = f.points_world
        assert len(p) > 500, len(p)
        r = np.hypot(p[:, 0] - x_c, p[:, 1] - 9.0)
        np.testing.assert_allclose(r, 0.4, atol=0.03)  # on its cylinder, where it is then
        assert p[:, 2].min() > -0.01 and p[:, 2].max() < 1.81
        xs.append(p[:, 0].mean())
    dt = (frames[-1].t_us - frames[0].t_us) * 1e-6
    assert abs((xs[1] - xs[0]) - SPEED * dt) < 0.3, (xs, dt)


def test_wire_trial_ends_as_mover_collision(tmp_path):
    """A ball waits 15 m up the start-goal line until navigation starts, then flies down
    it at 2 m/s at the start's altitude: the baseline navigator, flying the line, meets it
    head on, in-process and over MAVLink in lockstep, with the same row (the SITL side's
    guard ends the trial there)."""
    spec_file = _yard(tmp_path, "  - {shape: sphere, radius_m: 0.8, z_m: 1.5, "
                                "points: [[15, 20], [15, 2]], speed_m_s: 2.0}\n")
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="yard",
                     scenario_file=str(spec_file))
    inproc = run_trial(spec).row
    assert inproc["reason"] == "mover_collision", inproc["detail"]
    row = run_trial_lockstep(spec, log_dir=tmp_path, **worker_bus(None)).row
    # in lockstep the wire row is the in-process row but the wall times
    assert {k: (v, row[k]) for k, v in inproc.items() if k not in WALL_COLUMNS
            and json.dumps(v) != json.dumps(row[k])} == {}
    assert row["reason"] == "mover_collision", row["detail"]
    assert row["detail"].startswith("hit ball 1 (moving) at "), row["detail"]
    assert row["mover_count"] == 1 and row["nav_time_s"] > 0.5
    # they closed 15 m (less the ball's and the body's radii) at 2 m/s + the vehicle's speed
    assert row["nav_time_s"] < 15.0 / 2.0, row["nav_time_s"]
