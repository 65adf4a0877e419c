"""A lockstep step tick is answered by its setpoint *and* its acknowledgement, whatever
order they arrive in (issue 45: on a loaded machine MAVSDK's offboard setpoints, sent by
MAVSDK's own sending path, came behind the TIMESYNC acknowledgements MavlinkDirect puts
straight on the connection; the clock went on without them until the vehicle left
offboard, "the flight controller refused offboard mode").

The vehicle is the PX4 face serving a real trial's fleet on its own instance (lockstep:
links read only while the clock stands); the client is pymavlink, sending what
``ft-sitl navigate --lockstep`` sends, in the order a loaded machine delivered it: the
acknowledgement first, the setpoint after.
"""

import subprocess
import sys

import numpy as np
import pytest
from pymavlink import mavutil

from ft_sitl.autopilot.cascade import SP_POS
from ft_sitl.missions.protocol import TrialFailure
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.transport.lockstep import LockstepPilot
from ft_sitl.transport.wire_trial import WireTrial

pytestmark = pytest.mark.e2e  # (sockets and a process: tests/lanes.py)

#: the wall seconds the test gives a tick that lacks its setpoint before it calls it
#: unanswered (the pilot keeps waiting; the test only needs it not to have gone on)
NOT_ANSWERED_S = 1.0


def test_a_step_waits_for_its_setpoint_when_the_acknowledgement_overtakes_it(tmp_path):
    spec = TrialSpec(algorithm="straight", platform="1.00kg-SunnySky", family="forest",
                     scenario_index=2)
    trial = WireTrial(spec, log_dir=tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    client = None
    try:
        server, _ = trial.serve(lockstep=True)
        pilot = LockstepPilot(None, server, None, proc, trial.out_path, trial.err_path)
        port = server.links[0].listen[1]
        client = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                            source_component=190)
        mav = client.mav

        def ack(seq):
            mav.timesync_send(max(1, trial.fleet.time_us * 1000), seq)

        # tick 1 is a step: its acknowledgement arrives, its setpoint not yet
        before = pilot.setpoints
        ack(1)
        with pytest.raises(TrialFailure) as exc:
            pilot._wait(1, NOT_ANSWERED_S, "answer tick 1", setpoints_past=before)
        assert exc.value.reason is Outcome.NAVIGATOR_ERROR
        assert pilot.acked == 1  # (the acknowledgement was read: only the setpoint lacks)
        cmd = trial.fleet.commanders[0]
        assert cmd._offboard_sp is None
        # then the setpoint: now the tick is answered, and the vehicle holds that setpoint
        mav.set_position_target_local_ned_send(
            0, 1, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED, 0b0000_1111_1111_1000,
            1.0, 2.0, -3.0, 0, 0, 0, 0, 0, 0, 0.5, 0)
        pilot._wait(1, 60.0, "answer tick 1", setpoints_past=before)
        assert pilot.setpoints == before + 1
        sp = cmd._offboard_sp
        assert sp is not None
        origin = np.asarray(trial.plan.task().origin, dtype=float)
        # (local NED north 1, east 2, down -3 is ENU 2, 1, 3 from the origin)
        assert np.allclose(sp.row[SP_POS:SP_POS + 3], origin + [2.0, 1.0, 3.0])
        # an observe tick needs no setpoint: its acknowledgement answers it
        ack(2)
        pilot._wait(2, 60.0, "answer tick 2")
    finally:
        if client is not None:
            client.close()
        proc.kill()
        proc.wait(10)
        trial.close()


def test_a_trial_vehicle_serves_no_ground_station_link(tmp_path):
    """A wire trial's vehicle answers its client's link alone: a ground station on the
    machine (every instance sends its GCS link to 14550, MAVProxy or QGC there answers to
    whichever spoke last) cannot command it mid-trial; its GCS listen port stays free."""
    import socket

    from ft_sitl.mavlink.server import GCS_LISTEN_BASE

    spec = TrialSpec(algorithm="straight", platform="1.00kg-SunnySky", family="forest",
                     scenario_index=2)
    trial = WireTrial(spec, log_dir=tmp_path)
    try:
        server, _ = trial.serve(lockstep=True)
        api, gcs = server.links[0], server.links[1]
        assert api.transport is not None and gcs.transport is None
        assert gcs.listen[1] == GCS_LISTEN_BASE + server.base_instance
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(gcs.listen)  # nobody holds it
        server.pump(0.05)  # (serving without the link does not fail)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s, \
                pytest.raises(OSError):
            s.bind(api.listen)  # the client's link is served
    finally:
        trial.close()
