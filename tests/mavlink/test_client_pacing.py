"""Client pacing (SitlServer pace="client", ``ft-sitl sitl --pace client``): the simulated
clock never runs more than the span past the last message from a client, and a message
lets it go on; bad pacing options are one-line errors naming the option and its range."""

import subprocess
import sys
import time

import pytest
from pymavlink import mavutil

from ft_sitl import frames
from ft_sitl.mavlink.server import PACE_SPAN_DEFAULT_S, SitlServer, check_pacing
from ft_sitl.physics.catalog import get_platform
from ft_sitl.sim.fleet import Fleet
from tests.mavlink.sitl_harness import PLATFORM, free_sitl

SPAN_S = 0.05


def _wait(pred, what: str, timeout_s: float = 120.0) -> None:
    """Until ``pred()`` (a generous ceiling only against a hang: no timing is asserted)."""
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


@pytest.mark.e2e
def test_a_silent_client_holds_the_clock_and_a_message_releases_it():
    with free_sitl(speed_factor=5.0, pace="client", pace_span_s=SPAN_S) as server:
        span_us = round(SPAN_S * 1e6)
        fleet = server.fleet
        # no client has said anything: the clock stops within the span of the start
        _wait(lambda: server.held_s > 0.2, "the clock to be held")
        held_at = fleet.time_us
        assert held_at <= server.client_sim_us + span_us
        assert held_at <= span_us
        api = server.links[0].listen
        conn = mavutil.mavlink_connection(f"udpout:{api[0]}:{api[1]}", source_system=255,
                                          source_component=190)
        try:
            for k in range(1, 4):
                conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                        mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                _wait(lambda before=held_at: server.client_sim_us >= before,
                      "the server to read the heartbeat")
                # the message lets the clock run on, to at most the span past it
                _wait(lambda h=held_at: fleet.time_us > h, "the clock to run on")
                _wait(lambda: fleet.time_us + 4000 > server.client_sim_us + span_us,
                      "the clock to reach the span again")
                assert server.client_sim_us + span_us >= fleet.time_us
                held_at = fleet.time_us
                assert held_at <= k * span_us + span_us
        finally:
            conn.close()


@pytest.mark.e2e
def test_wall_pacing_runs_without_clients():
    with free_sitl(speed_factor=5.0) as server:
        assert server.pace == "wall" and server.pace_span_s is None
        _wait(lambda: server.fleet.time_us > 4 * round(SPAN_S * 1e6), "the clock to run")


def test_the_server_takes_the_pacing_arguments():
    fleet = Fleet([get_platform(PLATFORM)])
    geo = frames.GeoReference(*frames.PX4_SITL_HOME)
    s = SitlServer(fleet, geo, pace="client")
    assert s.pace_span_s == PACE_SPAN_DEFAULT_S
    assert SitlServer(fleet, geo, pace="client", pace_span_s=0.2).pace_span_s == 0.2
    assert SitlServer(fleet, geo).pace_span_s is None


@pytest.mark.parametrize("args,message", [
    ((1.0, "client", -0.1), "--pace-span: -0.1 must be within [0.004, 60] simulated seconds"),
    ((1.0, "client", 0.0), "--pace-span: 0.0 must be within [0.004, 60] simulated seconds"),
    ((1.0, "client", float("inf")), "--pace-span: inf must be within [0.004, 60]"),
    ((1.0, "wall", 0.05), "--pace-span: 0.05 is only for --pace client"),
    ((0.0, "client", 0.05), "--speed-factor: 0.0 must be within [0.01, 1000] (client pacing"),
    ((1.0, "lockstep", None), "--pace: 'lockstep' must be one of wall, client"),
])
def test_bad_pacing_options_are_one_line_errors(args, message):
    with pytest.raises(ValueError) as err:
        check_pacing(*args)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("argv,message", [
    (["--pace", "client", "--pace-span", "-1"],
     "ft-sitl: error: --pace-span: -1.0 must be within [0.004, 60] simulated seconds"),
    (["--pace", "client", "--pace-span", "0"],
     "ft-sitl: error: --pace-span: 0.0 must be within [0.004, 60] simulated seconds"),
    (["--pace-span", "0.1"], "ft-sitl: error: --pace-span: 0.1 is only for --pace client "
     "(wall pacing has no span)"),
    (["--pace", "client", "--speed-factor", "0"],
     "ft-sitl: error: --speed-factor: 0 must be within 0.01..1000"),
])
@pytest.mark.e2e
def test_the_cli_refuses_bad_pacing_in_one_line(argv, message):
    r = subprocess.run([sys.executable, "-m", "ft_sitl", "sitl", *argv], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip() == message
