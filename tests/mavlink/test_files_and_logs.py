"""Ground-station services beyond flying (issue #23, point 5): MAVLink FTP and log download
with MAVSDK's Ftp and LogFiles plugins, FTP refusals of bad input with pymavlink's raw
packets, and the fast, honest failures of the camera, gimbal and transponder plugins on
a vehicle that has none of them."""

import asyncio
import errno
import random

import pytest
from mavsdk.asyncio.plugins.camera import CameraAsync
from mavsdk.asyncio.plugins.ftp import FtpAsync
from mavsdk.asyncio.plugins.gimbal import GimbalAsync
from mavsdk.asyncio.plugins.log_files import LogFilesAsync
from mavsdk.asyncio.plugins.transponder import TransponderAsync
from mavsdk.plugins.camera import CameraError, CameraResult, Mode
from mavsdk.plugins.ftp import FilesystemEntry, FtpError, FtpResult
from mavsdk.plugins.gimbal import GimbalError, GimbalMode, SendMode
from mavsdk.plugins.log_files import LogFilesError, LogFilesResult
from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot.params import PARAMS
from ft_sitl.mavlink import ftp
from ft_sitl.mavlink.ftp import Err, Op

from .mavsdk_util import connect
from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import ack_of, client, wait_msg

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCES = (64, 65, 66)  # (ports of their own)


async def _download(plugin, remote, local_dir, burst):
    last = None
    async for progress in plugin.download(remote, str(local_dir), burst):
        last = progress
    return last


def test_ftp_and_log_download_with_mavsdk(tmp_path):
    tlog = tmp_path / "flight.tlog"

    async def run(server):
        m, drone = await connect(14540 + INSTANCES[0])
        files, logs = FtpAsync(drone), LogFilesAsync(drone)
        root = (await files.list_directory("/")).entries
        assert {(e.name, e.entry_type) for e in root} == {
            ("log", FilesystemEntry.EntryType.DIRECTORY),
            ("ft-sitl", FilesystemEntry.EntryType.DIRECTORY)}
        day = (await files.list_directory("/log")).entries
        assert len(day) == 1 and day[0].entry_type == FilesystemEntry.EntryType.DIRECTORY
        (log_entry,) = (await files.list_directory(f"/log/{day[0].name}")).entries
        assert log_entry.name.endswith(".tlog") and log_entry.size_bytes > 0

        # the parameter file, read-file by read-file, then checked by CRC32 on the vehicle
        await _download(files, "/ft-sitl/params.txt", tmp_path, False)
        lines = (tmp_path / "params.txt").read_text().splitlines()
        rows = [line.split("\t") for line in lines if not line.startswith("#")]
        assert [r[2] for r in rows] == list(PARAMS)
        cruise = repr(server.fleet.params[0]["MPC_XY_CRUISE"])
        assert ["1", "1", "MPC_XY_CRUISE", cruise, str(mav.MAV_PARAM_TYPE_REAL32)] in rows
        assert await files.are_files_identical(str(tmp_path / "params.txt"),
                                               "/ft-sitl/params.txt")
        # the telemetry log in bursts: the bytes the file held when it was opened
        remote = f"/log/{day[0].name}/{log_entry.name}"
        (tmp_path / "burst").mkdir()  # (MAVSDK's burst download does not create it)
        await _download(files, remote, tmp_path / "burst", True)
        got = (tmp_path / "burst" / log_entry.name).read_bytes()
        assert len(got) >= log_entry.size_bytes and got == tlog.read_bytes()[:len(got)]

        with pytest.raises(FtpError) as err:
            await files.create_directory("/ft-sitl/new")
        assert err.value.result == FtpResult.FILE_PROTECTED
        with pytest.raises(FtpError) as err:
            await _download(files, "/fs/microsd/log/none.ulg", tmp_path, False)
        assert err.value.result == FtpResult.FILE_DOES_NOT_EXIST

        # the same log through the log protocol
        (entry,) = await logs.get_entries()
        assert entry.id == 0 and entry.size_bytes >= log_entry.size_bytes
        target = tmp_path / "log-0.tlog"
        steps = [step async for step in logs.download_log_file(entry, str(target))]
        assert steps[-1][0] == LogFilesResult.SUCCESS
        assert target.read_bytes() == tlog.read_bytes()[:entry.size_bytes]
        m.destroy()

    with running_sitl(base_instance=INSTANCES[0], tlog=tlog) as server:
        asyncio.run(run(server))


def _ftp_request(c, seq, opcode, data=b"", offset=0, session=0, size=None):
    h = ftp.Header(seq, session, opcode, 0, 0, 0, offset)
    payload = ftp.pack(h, data)
    if size is not None:
        payload[4] = size  # a size field that does not match the data
    c.mav.file_transfer_protocol_send(0, 1, 1, payload)
    reply = wait_msg(c, "FILE_TRANSFER_PROTOCOL",
                     lambda m: ftp.unpack(m.payload)[0].seq == (seq + 1) & 0xFFFF, timeout=3)
    return ftp.unpack(reply.payload)


def test_ftp_refuses_bad_input_and_the_vehicle_carries_on():
    with running_sitl(base_instance=INSTANCES[1]):
        c = client(14540 + INSTANCES[1])
        h, data = _ftp_request(c, 10, Op.READ_FILE, offset=0, size=10)
        assert (h.opcode, h.req_opcode, data) == (Op.NAK, Op.READ_FILE,
                                                  bytes([Err.INVALID_SESSION]))
        h, data = _ftp_request(c, 11, Op.OPEN_FILE_RO, b"/log/../../etc/passwd\0")
        assert (h.opcode, data) == (Op.NAK, bytes([Err.FAIL_ERRNO, errno.EACCES]))
        h, data = _ftp_request(c, 12, Op.LIST_DIRECTORY, b"/" + b"x" * 238, size=239)
        assert (h.opcode, data) == (Op.NAK, bytes([Err.FAIL_ERRNO, errno.ENAMETOOLONG]))
        h, data = _ftp_request(c, 13, Op.LIST_DIRECTORY, b"/\0", size=250)
        assert (h.opcode, data) == (Op.NAK, bytes([Err.INVALID_DATA_SIZE]))
        h, data = _ftp_request(c, 14, Op.CREATE_FILE, b"/ft-sitl/evil\0")
        assert (h.opcode, data) == (Op.NAK, bytes([Err.FILE_PROTECTED]))
        h, data = _ftp_request(c, 15, 99)
        assert (h.opcode, data) == (Op.NAK, bytes([Err.UNKNOWN_COMMAND]))
        # an open repeated (its answer lost) is answered again; a read past the end; a
        # second open while the first is held
        h, data = _ftp_request(c, 16, Op.OPEN_FILE_RO, b"/ft-sitl/params.txt\0")
        assert (h.opcode, h.session) == (Op.ACK, 0)
        size = int.from_bytes(data, "little")
        h, data = _ftp_request(c, 16, Op.OPEN_FILE_RO, b"/ft-sitl/params.txt\0")
        assert (h.opcode, int.from_bytes(data, "little")) == (Op.ACK, size)
        h, data = _ftp_request(c, 17, Op.READ_FILE, offset=size, size=100)
        assert (h.opcode, data) == (Op.NAK, bytes([Err.EOF]))
        h, data = _ftp_request(c, 18, Op.READ_FILE, offset=0, session=5, size=100)
        assert (h.opcode, data) == (Op.NAK, bytes([Err.INVALID_SESSION]))
        h, data = _ftp_request(c, 19, Op.OPEN_FILE_RO, b"/ft-sitl/params.txt\0")
        assert (h.opcode, data) == (Op.NAK, bytes([Err.NO_SESSIONS_AVAILABLE]))
        assert _ftp_request(c, 20, Op.TERMINATE_SESSION)[0].opcode == Op.ACK
        # no logs without --tlog: the list says so at once, a data request is answered
        c.mav.log_request_list_send(1, 1, 0, 0xFFFF)
        entry = wait_msg(c, "LOG_ENTRY", timeout=3)  # (it raises after 3 s without one)
        assert (entry.num_logs, entry.id) == (0, 0)
        c.mav.log_request_data_send(1, 1, 3, 0, 1000)
        assert wait_msg(c, "LOG_DATA", timeout=3).count == 0
        # random FTP payloads and log requests: each answered or dropped, never a crash
        rng = random.Random(23)
        for k in range(200):
            payload = list(rng.randbytes(ftp.PAYLOAD_LEN))
            payload[3] = rng.choice([*Op, 16, 200]) if k % 2 else payload[3]
            c.mav.file_transfer_protocol_send(0, 1, 1, payload)
            c.mav.log_request_data_send(1, 1, rng.randrange(3), rng.randrange(2**32),
                                        rng.randrange(2**32))
        c.mav.log_request_end_send(1, 1)
        # the vehicle is alive and its FTP still works
        wait_msg(c, "HEARTBEAT", timeout=3)
        h, data = _ftp_request(c, 21, Op.LIST_DIRECTORY, b"/\0")
        assert (h.opcode, data) == (Op.ACK, b"Dft-sitl\0Dlog\0")


def test_camera_gimbal_transponder_and_logs_fail_fast():
    async def run():
        m, drone = await connect(14540 + INSTANCES[2])
        camera, gimbal = CameraAsync(drone), GimbalAsync(drone)
        transponder, logs = TransponderAsync(drone), LogFilesAsync(drone)

        async def refused(call, error, result=None):
            # answered, not left to time out: a hang trips wait_for, MAVSDK's own
            # command timeout is a TIMEOUT result
            with pytest.raises(error) as err:
                await asyncio.wait_for(call, 5)
            assert "TIMEOUT" not in str(err.value.result)
            if result is not None:
                assert err.value.result == result

        # camera commands to the autopilot: COMMAND_ACK UNSUPPORTED
        await refused(camera.take_photo(1), CameraError, CameraResult.ACTION_UNSUPPORTED)
        await refused(camera.set_mode(1, Mode.VIDEO), CameraError,
                      CameraResult.ACTION_UNSUPPORTED)
        await refused(camera.start_video(1), CameraError, CameraResult.ACTION_UNSUPPORTED)
        await refused(gimbal.set_angles(0, 0.0, -90.0, 0.0, GimbalMode.YAW_FOLLOW,
                                        SendMode.ONCE), GimbalError)
        # accepted, as PX4 (its ADSB_VEHICLE stream: the movers' traffic); an error raises
        await asyncio.wait_for(transponder.set_rate_transponder(1.0), 5)
        await refused(logs.get_entries(), LogFilesError, LogFilesResult.NO_LOGFILES)
        m.destroy()

    with running_sitl(base_instance=INSTANCES[2]):
        # what those plugins send, and the gimbal commands of older clients, raw
        c = client(14540 + INSTANCES[2])
        for command, params, want in (
                (mav.MAV_CMD_REQUEST_MESSAGE, [mav.MAVLINK_MSG_ID_CAMERA_INFORMATION],
                 mav.MAV_RESULT_DENIED),  # as PX4: a message it has no stream for
                (mav.MAV_CMD_REQUEST_MESSAGE, [mav.MAVLINK_MSG_ID_GIMBAL_MANAGER_INFORMATION],
                 mav.MAV_RESULT_DENIED),
                (mav.MAV_CMD_DO_MOUNT_CONTROL, [-45.0, 0.0, 0.0], mav.MAV_RESULT_UNSUPPORTED),
                (mav.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, [-45.0, 0.0],
                 mav.MAV_RESULT_UNSUPPORTED)):
            c.mav.command_long_send(1, 1, command, 0, *(params + [0.0] * (7 - len(params))))
            assert ack_of(c, command, timeout=3).result == want
        # a message it cannot produce is FAILED to SET_MESSAGE_INTERVAL, as PX4
        c.mav.command_long_send(1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                mav.MAVLINK_MSG_ID_CAMERA_INFORMATION, 1e6, 0, 0, 0, 0, 0)
        assert ack_of(c, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 3).result == mav.MAV_RESULT_FAILED
        c.mav.command_long_send(1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                mav.MAVLINK_MSG_ID_ADSB_VEHICLE, 1e6, 0, 0, 0, 0, 0)
        assert ack_of(c, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 3).result == mav.MAV_RESULT_ACCEPTED
        c.close()
        asyncio.run(run())
