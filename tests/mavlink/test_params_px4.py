"""PX4's parameters over MAVLink (pymavlink, real sockets): the ones scripts set
(COM_RCL_EXCEPT, NAV_DLL_ACT, ...) are accepted, echoed with their type and read back;
out-of-range values are refused; PARAM_REQUEST_LIST streams every parameter."""

import struct
import time

import pytest
from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot.params import PARAMS

from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import client, wait_msg

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

#: instance 7 (ports 14587 and 14547): clear of the other MAVLink tests' instances
BASE = 7
INT32, REAL32 = mav.MAV_PARAM_TYPE_INT32, mav.MAV_PARAM_TYPE_REAL32


def to_wire(v: int) -> float:
    return struct.unpack("<f", struct.pack("<i", v))[0]


def from_wire(f: float) -> int:
    return struct.unpack("<i", struct.pack("<f", f))[0]


def param_set(c, name: str, value, is_int: bool):
    c.mav.param_set_send(1, 1, name.encode(), to_wire(value) if is_int else value,
                         INT32 if is_int else REAL32)
    return wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == name, timeout=5)


def param_read(c, name: str):
    c.mav.param_request_read_send(1, 1, name.encode(), -1)
    return wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == name, timeout=5)


def test_stored_parameters_set_read_back_and_refused_as_px4_refuses():
    index = {n: k for k, n in enumerate(PARAMS)}
    with running_sitl(base_instance=BASE) as server:
        c = client(14540 + BASE)
        for name, value in [("COM_RCL_EXCEPT", 4), ("NAV_DLL_ACT", 2), ("COM_OBL_RC_ACT", 1),
                            ("SYS_FAILURE_EN", 1)]:
            for pv in (param_set(c, name, value, True), param_read(c, name)):
                assert (pv.param_type, from_wire(pv.param_value)) == (INT32, value), name
                assert (pv.param_count, pv.param_index) == (len(PARAMS), index[name])
            assert server.fleet.params[0][name] == value
        pv = param_set(c, "MPC_XY_TRAJ_P", 0.75, False)
        assert (pv.param_type, pv.param_value) == (REAL32, 0.75)
        assert param_read(c, "MPC_XY_TRAJ_P").param_value == 0.75
        # out of PX4's published range: refused, the value kept and echoed, a warning
        for name, bad, kept in [("COM_RCL_EXCEPT", 32, 4), ("NAV_DLL_ACT", 7, 2),
                                ("SYS_FAILURE_EN", 2, 1)]:
            assert from_wire(param_set(c, name, bad, True).param_value) == kept, name
        assert param_set(c, "MPC_XY_TRAJ_P", 1.5, False).param_value == 0.75
        text = wait_msg(c, "STATUSTEXT", lambda m: m.text.startswith("MPC_XY_TRAJ_P"))
        assert text.text == "MPC_XY_TRAJ_P: 1.5 is outside [0.1, 1]"
        assert text.severity == mav.MAV_SEVERITY_WARNING
        assert server.fleet.params[0]["MPC_XY_TRAJ_P"] == 0.75
        assert server.fleet.params[0]["COM_RCL_EXCEPT"] == 4


def test_param_request_list_streams_every_parameter_once_in_order():
    n = len(PARAMS)
    with running_sitl(base_instance=BASE, speed_factor=1.0) as server:
        server.fleet.params[0].set("COM_RCL_EXCEPT", 5)
        c = client(14540 + BASE)
        c.mav.param_request_list_send(1, 1)
        got = {}
        end = time.time() + 20
        while len(got) < n and time.time() < end:
            m = c.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if m is not None:
                assert m.param_count == n
                assert m.param_index not in got, "sent twice"
                got[m.param_index] = m
        assert sorted(got) == list(range(n)), f"{n - len(got)} missing"
        assert [got[k].param_id for k in range(n)] == list(PARAMS)
        for k, (name, spec) in enumerate(PARAMS.items()):
            m = got[k]
            assert m.param_type == (INT32 if spec.is_int else REAL32), name
            value = from_wire(m.param_value) if spec.is_int else m.param_value
            want = 5 if name == "COM_RCL_EXCEPT" else spec.default
            assert value == pytest.approx(want, rel=1e-6), name
