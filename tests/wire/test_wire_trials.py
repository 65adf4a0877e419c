"""Trials over the wire with real components: the SITL on UDP, MAVSDK client processes
(``ft-sitl navigate`` and a user's script), the MQTT bus through mosquitto and the embedded
broker; the outcome judged by the in-process protocol's code."""

import asyncio
import json
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from ft_sitl.bus.client import BusClient
from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import load_campaign
from ft_sitl.missions.executors import DaskExecutor
from ft_sitl.missions.trial import TrialSpec
from ft_sitl.transport import transport
from ft_sitl.transport.mavlink_trial import run_trial_wire, worker_bus

from ..bus.conftest import Mosquitto, free_port

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

AGILE = "0.98kg-EGO Planner DIY"
REPO = Path(__file__).resolve().parents[2]
FT_SITL = str(Path(sys.executable).parent / "ft-sitl")
#: the columns that measure wall time (and when the row was written): all others of a
#: lockstep wire row equal the in-process row's
WALL_COLUMNS = ("wall_time_s", "planner_time_s", "finished_utc")


def _rows(out: Path) -> dict:
    return {(r["algorithm"], r["family"], r["scenario_index"]): r
            for r in map(json.loads, (out / "trials.jsonl").read_text().splitlines())}


def test_inprocess_and_mavlink_transports_agree(tmp_path, navrl_checkpoint, monkeypatch):
    """The small version of docs/wire.md's agreement check: the same trials (same seeds)
    in-process and over MAVLink in lockstep (ft-sitl navigate --lockstep as a MAVSDK
    client process, observations and depth frames as ticks on the embedded MQTT broker,
    setpoints and tick acknowledgements on MAVLink): every row is the in-process row
    column for column but the wall times, whatever the host's speed or load."""
    monkeypatch.setenv("FT_SITL_NAVRL_CHECKPOINT", str(navrl_checkpoint))
    p = tmp_path / "c.toml"
    p.write_text(textwrap.dedent(f"""\
        name = "agree"
        trials = 1
        platforms = ["{AGILE}"]
        scenarios = [{{family = "forest", indices = [1]}}]
        algorithms = ["straight", "navrl", "ego"]
        """))  # (one family: the suite's time; docs/results/wire-agreement has the rest)
    c = load_campaign(p)
    run_campaign(c, tmp_path / "inproc", progress=False)
    run_campaign(c, tmp_path / "wire", progress=False, transport=transport("mavlink"))
    a, b = _rows(tmp_path / "inproc"), _rows(tmp_path / "wire")
    assert a.keys() == b.keys() and len(a) == 3
    for key in a:
        here, there = a[key], b[key]
        assert here["protocol_version"] == 11
        differ = {k: (here[k], there.get(k)) for k in here
                  if k not in WALL_COLUMNS and json.dumps(here[k]) != json.dumps(there.get(k))}
        assert not differ, (key, differ)
    assert a[("navrl", "forest", 1)]["success"]
    runs = json.loads((tmp_path / "wire" / "runs.json").read_text())
    assert runs[-1]["transport"] == "mavlink" and runs[-1]["lockstep"] is True


def test_mavlink_trials_on_a_dask_cluster_fly_side_by_side(tmp_path):
    """Two Dask workers on this machine each serve a SITL vehicle at once, in lockstep:
    each trial process takes its own instance number, so the UDP ports never collide, and
    each row is the in-process row column for column but the wall times, however busy the
    host."""
    p = tmp_path / "c.toml"
    p.write_text(textwrap.dedent(f"""\
        name = "side-by-side"
        trials = 1
        platforms = ["{AGILE}"]
        scenarios = [{{family = "forest", indices = [1]}}, {{family = "urban", indices = [1]}}]
        algorithms = ["straight"]
        """))
    c = load_campaign(p)
    run_campaign(c, tmp_path / "inproc", progress=False)
    ex = DaskExecutor(local_workers=2, chunk_max=1)
    run_campaign(c, tmp_path / "wire", progress=False, executor=ex,
                 transport=transport("mavlink"))
    a, b = _rows(tmp_path / "inproc"), _rows(tmp_path / "wire")
    assert a.keys() == b.keys() and len(a) == 2
    for key in a:
        assert b[key]["nav_time_s"] > 0.0, (key, b[key]["detail"])
        differ = {k: (a[key][k], b[key].get(k)) for k in a[key] if k not in WALL_COLUMNS
                  and json.dumps(a[key][k]) != json.dumps(b[key].get(k))}
        assert not differ, (key, differ)
    run = json.loads((tmp_path / "wire" / "runs.json").read_text())[-1]
    assert (run["executor"], run["transport"], run["lockstep"]) == ("dask", "mavlink", True)
    assert len(run["throughput"]) == 2  # one trial on each worker


def _command_spec(argv, **kw):
    return TrialSpec(algorithm="command", algorithm_params={"argv": argv}, platform=AGILE,
                     family="forest", scenario_index=2, label="user", **kw)


#: a client's pacing span (s): half the offboard-loss timeout (COM_OF_LOSS_T, 1 s), so a
#: client starved of CPU (it streams its setpoints) never loses offboard control
USER_SPAN_S = 0.5


def test_user_scripts_crashing_hanging_or_flying(tmp_path):
    """A user's command navigator cannot answer lockstep ticks: the flying one is served
    client-paced (a starved script sees a slower world), the speed factor the ceiling."""
    bus = worker_bus(None)
    crash = run_trial_wire(_command_spec([sys.executable, "-c",
                                          "import sys; print('no map here', file=sys.stderr);"
                                          " sys.exit(2)"]), log_dir=tmp_path, **bus).row
    assert crash["reason"] == "navigator_error" and "no map here" in crash["detail"]
    hang = run_trial_wire(_command_spec([sys.executable, "-c", "import time; time.sleep(600)"]),
                          arm_timeout_s=8.0, log_dir=tmp_path, **bus).row
    assert hang["reason"] == "navigator_error" and "not armed within 8 s" in hang["detail"]
    flown = run_trial_wire(_command_spec([sys.executable,
                                          str(REPO / "examples" / "user_navigator.py")]),
                           speed_factor=3.0, pace_span_s=USER_SPAN_S, log_dir=tmp_path,
                           **bus).row
    # the example climbs 0.5 m and flies the straight line: it navigated and was judged
    assert flown["nav_time_s"] > 1.0 and flown["reason"] != "navigator_error", flown["detail"]
    assert flown["path_length_m"] > 3.0


def test_a_fence_that_refuses_arming_ends_a_wire_trial_as_in_process(tmp_path):
    from ft_sitl.missions.resources import RESOURCES
    from ft_sitl.missions.trial import run_trial

    argv = [sys.executable, str(REPO / "examples" / "user_navigator.py")]
    takeoff = RESOURCES.scenario(_command_spec(argv)).takeoff
    fence = {"action": "hold", "circles": [  # keep out of where it stands
        {"inclusion": False, "center": [float(takeoff[0]), float(takeoff[1])],
         "radius_m": 1.0}]}
    row = run_trial_wire(_command_spec(argv, fence=fence), arm_timeout_s=20.0,
                         log_dir=tmp_path, **worker_bus(None)).row
    assert (row["reason"], row["detail"]) == (
        "geofence", "arming refused: Preflight Fail: Geofence violation")
    assert row["nav_time_s"] == 0.0
    # the same rule in-process (with a navigator of ours: the outcome comes before it flies)
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="forest", scenario_index=2,
                     fence=fence)
    assert run_trial(spec).row["detail"] == row["detail"]


def test_bad_placeholder_in_a_command_fails_only_its_trial(tmp_path):
    row = run_trial_wire(_command_spec(["python", "{nope}"]), log_dir=tmp_path,
                         **worker_bus(None)).row
    assert row["reason"] == "navigator_error" and "bad placeholder" in row["detail"]


def test_navigate_cli_against_sitl_cli_through_mosquitto(tmp_path):
    """The two commands a user runs, with a user scenario: a wall beside the line, which the
    planner sees through depth frames carried by mosquitto."""
    from ..missions.conftest import write_yard

    yard = str(write_yard(tmp_path / "yard", wall=((6.0, 8.0, 0.0), (8.0, 12.0, 3.0))))
    broker = Mosquitto(tmp_path / "mq").start()
    inst = 14
    # client-paced: a navigator starved of CPU sees a slower world (it streams setpoints)
    sitl = subprocess.Popen([FT_SITL, "sitl", "--scenario", yard, "--instance", str(inst),
                             "--speed-factor", "1", "--pace", "client", "--pace-span",
                             str(USER_SPAN_S), "--mqtt", broker.url, "--duration", "400"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        nav = subprocess.run([FT_SITL, "navigate", "--algorithm", "ego", "--scenario",
                              yard, "--connect", f"udpin://0.0.0.0:{14540 + inst}",
                              "--mqtt", broker.url, "--vehicle", str(inst), "--json",
                              "--quiet", "--max-speed", "2"],
                             capture_output=True, text=True, timeout=400)
        assert nav.returncode == 0, nav.stdout[-2000:] + nav.stderr[-2000:]
        assert json.loads(nav.stdout.strip().splitlines()[-1])["result"] == "success"
    finally:
        sitl.terminate()
        out, err = sitl.communicate(timeout=30)
        broker.kill()
    assert "MQTT bus (broker)" in out
    # events and telemetry are never dropped; a depth frame (lowest priority, its queue
    # short because a frame is stale at the next one) may be under load, rarely
    stats = re.search(r"bus vehicle \d+: (\d+) messages sent, dropped: ([^;]*);", err)
    assert stats, err
    sent, dropped = int(stats.group(1)), stats.group(2)
    counts = dict(re.findall(r"(\w+) (\d+)", dropped)) if dropped != "none" else {}
    assert set(counts) <= {"depth"}, err
    assert int(counts.get("depth", 0)) <= 0.01 * sent, err


def test_sitl_wind_reaches_the_vehicle_and_the_bus(tmp_path):
    """`ft-sitl sitl --wind`: the hovering-on-the-ground vehicle's telemetry carries the
    wind (a steady 6 m/s from the west blows east: +x in ENU), turbulent when asked.
    `--estimator` and `--actuators` are taken too; the bus publishes the truth, not the
    flight controller's biased estimate. Bad settings of each are one error line."""
    broker = Mosquitto(tmp_path / "mq").start()
    inst = 16
    sitl = subprocess.Popen([FT_SITL, "sitl", "--instance", str(inst), "--speed-factor", "2",
                             "--mqtt", broker.url, "--duration", "60", "--wind",
                             "speed_m_s=6,from_deg=270,turbulence=light", "--wind-seed", "3",
                             "--estimator", "position_bias_m=0:0:0.5",
                             "--actuators", "efficiency=0.9"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    async def winds():
        out, heights = [], []
        async with BusClient(broker.url, str(inst), kinds=("telemetry",)) as client:
            # a ceiling against a hang (the start-up is long when numba compiles afresh)
            async with asyncio.timeout(300):
                while len(out) < 100:
                    msg = await client.receive()
                    out.append(msg.data.wind_world_m_s)
                    heights.append(msg.data.p_world_m[2])
        return np.array(out), np.array(heights)

    try:
        w, z = asyncio.run(winds())
    finally:
        sitl.terminate()
        out, err = sitl.communicate(timeout=30)
        broker.kill()
    assert "wind: speed_m_s 6, from_deg 270, turbulence light" in out, out + err
    assert "estimator: position_bias_m [0.0, 0.0, 0.5]" in out
    assert "actuators: efficiency 0.9" in out
    assert 3.0 < w[:, 0].mean() < 9.0 and abs(w[:, 1].mean()) < 3.0
    assert w[:, 0].std() > 0.05  # turbulent, not a constant
    assert np.abs(z).max() < 0.05  # on the ground: the truth (the estimate says 0.5 m)
    for option, value, message in (
            ("--wind", "speed_m_s=-1", "--wind: speed_m_s: must be a number 0..40 (m/s), "
                                       "got -1"),
            ("--estimator", "position_bias_m=1:2", "--estimator: position_bias_m: must be 3 "
                                                   "numbers, each -100..100 (m), got [1.0, 2.0]"),
            ("--actuators", "fail_motor=7", "--actuators: fail_motor: 7 must be within 0..4 "
                                            "(the platform's motors)")):
        bad = subprocess.run([FT_SITL, "sitl", option, value], capture_output=True,
                             text=True, timeout=60)
        assert bad.returncode == 2
        assert bad.stderr.strip() == f"ft-sitl: error: {message}"


def test_broker_killed_mid_flight_the_vehicle_flies_on_and_the_bus_reconnects(tmp_path):
    """Kill mosquitto while a MAVSDK navigator (not using the bus) flies; restart it on the
    same port: the flight reaches its goal, the bus reconnects, the drops are reported."""
    port = free_port()
    broker = Mosquitto(tmp_path / "mq", port=port).start()
    inst = 15
    sitl = subprocess.Popen([FT_SITL, "sitl", "--instance", str(inst), "--speed-factor", "2",
                             "--pace", "client", "--pace-span", str(USER_SPAN_S),
                             "--mqtt", broker.url, "--duration", "300"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    nav = subprocess.Popen([FT_SITL, "navigate", "--algorithm", "straight", "--goal",
                            "150,0,-2", "--connect", f"udpin://0.0.0.0:{14540 + inst}",
                            "--speed-factor", "2", "--json", "--quiet"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen = []

    async def listen(deadline_s):
        async with BusClient(broker.url, str(inst), kinds=("telemetry",)) as bus:
            async with asyncio.timeout(deadline_s):
                while True:
                    msg = await bus.receive()
                    seen.append(msg.data.time_usec)
                    if len(seen) > 20:
                        return

    try:
        asyncio.run(listen(60))
        broker.kill()
        t_kill = seen[-1]
        time.sleep(4.0)  # the vehicle flies on without a broker
        assert sitl.poll() is None and nav.poll() is None
        broker = Mosquitto(tmp_path / "mq2", port=port).start()
        seen.clear()
        asyncio.run(listen(60))
        assert min(seen) > t_kill + 2_000_000  # telemetry again, from later simulated time
        out_nav, err_nav = nav.communicate(timeout=400)
        assert nav.returncode == 0, out_nav + err_nav[-2000:]
        assert json.loads(out_nav.strip().splitlines()[-1])["result"] == "success"
    finally:
        for p in (nav, sitl):
            if p.poll() is None:
                p.terminate()
        out, err = sitl.communicate(timeout=30)
        broker.kill()
    summary = [ln for ln in err.splitlines() if ln.startswith("bus vehicle")][-1]
    assert "dropped: none" not in summary and "telemetry" in summary, summary
    reconnects = int(summary.split(";")[-1].split()[0])
    assert reconnects >= 1, summary
