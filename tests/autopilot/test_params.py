"""The parameter table: honoured ParamSpecs plus PX4's stored parameters (one declaration
each), range checks as PX4 publishes them, and where ft-sitl deliberately differs."""

import json
import math
from pathlib import Path

import pytest

from ft_sitl.autopilot import params as P
from ft_sitl.autopilot.params import PARAMS, PX4_TABLE, ParamError, ParamSet

ROOT = Path(__file__).resolve().parents[2]

#: Every honoured parameter whose type, default or range is not PX4 v1.15.2's, and why.
#: A change to a ParamSpec or to the table shows up here; (ft-sitl, PX4), None: PX4 gives
#: no bound.
DIFFERENCES = {
    # the FLYINGTRUST protocol's speed limit (benchmark)
    "MPC_XY_VEL_MAX": {"default": (4.0, 12.0)},
    # ft-sitl's controller limits, kept as the benchmark was flown with them
    "MPC_ACC_HOR_MAX": {"default": (3.0, 5.0), "min": (1.0, 2.0)},
    "MPC_ACC_UP_MAX": {"min": (1.0, 2.0)},
    "MPC_ACC_DOWN_MAX": {"min": (1.0, 2.0)},
    "MPC_THR_MAX": {"min": (0.1, 0.0)},
    "MPC_XY_VEL_D_ACC": {"min": (0.0, 0.1)},
    "NAV_ACC_RAD": {"default": (2.0, 10.0)},
    # PX4 (since v1.14) calls it CA_AIRMODE, in the control allocator
    "MC_AIRMODE": {"name": ("MC_AIRMODE", None)},
    # upper bounds ft-sitl adds where PX4 publishes none
    "MC_ROLLRATE_I": {"max": (10.0, None)},
    "MC_PITCHRATE_I": {"max": (10.0, None)},
    "MC_PITCHRATE_D": {"max": (0.01, None)},
    "MC_YAWRATE_I": {"max": (10.0, None)},
    "MC_YAWRATE_D": {"max": (0.01, None)},
    "MC_RR_INT_LIM": {"max": (1.0, None)},
    "MC_PR_INT_LIM": {"max": (1.0, None)},
    "MC_YR_INT_LIM": {"max": (1.0, None)},
    "MIS_TAKEOFF_ALT": {"max": (80.0, None)},
    "RTL_RETURN_ALT": {"max": (150.0, None)},
    "MPC_LAND_SPEED": {"max": (3.0, None)},
    "COM_DISARM_LAND": {"min": (-1.0, None), "max": (20.0, None)},
    "COM_DISARM_PRFLT": {"min": (-1.0, None), "max": (20.0, None)},
}


def test_honoured_parameters_differ_from_px4_only_where_listed():
    assert P.px4_differences() == DIFFERENCES


def test_one_declaration_per_parameter_honoured_first():
    honoured = [n for n, s in PARAMS.items() if s.honoured]
    stored = [n for n, s in PARAMS.items() if not s.honoured]
    assert list(PARAMS) == honoured + stored  # PARAM_VALUE's index order
    assert honoured == list(P.HONOURED) and len(honoured) == 80
    assert stored == sorted(set(PX4_TABLE) - set(P.HONOURED))
    assert len(PARAMS) == len(set(PX4_TABLE) | set(P.HONOURED)) == 479
    assert all(len(n) <= 16 for n in PARAMS)  # MAVLink's param_id
    # the honoured spec is the declaration: its default is ft-sitl's, not the table's
    assert PARAMS["MPC_XY_VEL_MAX"].default == 4.0 and PX4_TABLE["MPC_XY_VEL_MAX"].default == 12
    assert PARAMS["MPC_XY_VEL_MAX"].group == "Multicopter Position Control"
    assert PARAMS["FT_GAIN_MODE"].group == "ft-sitl"
    ps = ParamSet()
    for name, spec in PARAMS.items():  # every default passes its own checks
        assert ps.set(name, spec.default) == spec.default, name


def test_table_records_its_px4_release_and_matches_the_descriptions():
    doc = json.loads((ROOT / "ft_sitl/autopilot/data/px4_params.json").read_text())
    assert (doc["px4_release"], doc["px4_commit"]) == ("v1.15.2", "4817c0618a")
    assert doc["count"] == len(doc["params"]) == len(PX4_TABLE) == 470
    ours = dict(line.split("\t", 1) for line in
                (ROOT / "scripts/px4_param_descriptions.tsv").read_text().splitlines()
                if line and not line.startswith("#"))
    assert {n: s.doc for n, s in PX4_TABLE.items()} == ours
    for name in ("COM_RCL_EXCEPT", "NAV_DLL_ACT", "NAV_RCL_ACT", "COM_OBL_RC_ACT", "GF_ACTION",
                 "RTL_TYPE", "MIS_TKO_LAND_REQ", "FLW_TGT_MAX_VEL", "SYS_FAILURE_EN",
                 "SYS_AUTOSTART", "BAT1_CAPACITY", "EKF2_HGT_REF", "EKF2_GPS_CTRL",
                 "EKF2_EV_CTRL", "MAV_SYS_ID", "MAV_0_CONFIG", "CBRK_USB_CHK", "MC_ROLLRATE_K",
                 "MPC_JERK_AUTO", "LNDMC_Z_VEL_MAX"):
        assert name in PX4_TABLE, name


@pytest.mark.parametrize("name,type_,default,lo,hi,unit", [
    ("COM_RC_OVERRIDE", "INT32", 1, 0, 3, ""),
    ("NAV_DLL_ACT", "INT32", 0, 0, 6, ""),
    ("COM_RC_ARM_HYST", "INT32", 1000, 100, 1500, "ms"),
    ("COM_OBL_RC_ACT", "INT32", 0, None, None, ""),
    ("GF_PREDICT", "INT32", 0, 0, 1, ""),  # a boolean: 0 or 1
    ("MPC_XY_TRAJ_P", "FLOAT", 0.5, 0.1, 1.0, ""),
    ("MPC_ACC_HOR", "FLOAT", 3.0, 2.0, 15.0, "m/s^2"),
    ("MPC_VEL_MAN_BACK", "FLOAT", -1.0, -1.0, 20.0, "m/s"),
    ("COM_DL_LOSS_T", "INT32", 10, 5, 300, "s"),
    ("MAV_SYS_ID", "INT32", 1, 1, 250, ""),
    ("MAV_0_CONFIG", "INT32", 101, None, None, ""),
    ("BAT1_CAPACITY", "FLOAT", -1.0, -1.0, 100000.0, "mAh"),
    ("EKF2_GPS_CTRL", "INT32", 7, 0, 15, ""),
    ("EKF2_HGT_REF", "INT32", 1, None, None, ""),
    ("CBRK_USB_CHK", "INT32", 197848, 0, 197848, ""),
])
def test_stored_parameters_carry_px4s_facts(name, type_, default, lo, hi, unit):
    s = PARAMS[name]
    assert not s.honoured
    assert (s.px4_type, s.default, s.unit) == (type_, default, unit)
    assert (s.lo if s.bounded_lo else None, s.hi if s.bounded_hi else None) == (lo, hi)
    assert isinstance(s.default, int) == (type_ == "INT32")


def test_stored_parameters_are_set_and_range_checked():
    ps = ParamSet({"COM_RCL_EXCEPT": 4, "MPC_XY_TRAJ_P": 0.75})
    assert ps["COM_RCL_EXCEPT"] == 4 and ps["MPC_XY_TRAJ_P"] == 0.75
    assert ps.set("GF_PREDICT", 1) == 1 and isinstance(ps["GF_PREDICT"], int)
    assert ps.set("COM_OBL_RC_ACT", 7) == 7  # an enum PX4 gives no range: any INT32
    for name, value, message in [
        ("COM_RCL_EXCEPT", 32, "COM_RCL_EXCEPT: 32 is outside [0, 31]"),
        ("NAV_DLL_ACT", -1, "NAV_DLL_ACT: -1 is outside [0, 6]"),
        ("GF_PREDICT", 2, "GF_PREDICT: 2 is outside [0, 1]"),
        ("MPC_XY_TRAJ_P", 1.5, "MPC_XY_TRAJ_P: 1.5 is outside [0.1, 1]"),
        ("COM_FAIL_ACT_T", -5.0, "COM_FAIL_ACT_T: -5.0 s is outside [0, 25] s"),
        ("COM_OBL_RC_ACT", 2**31, "COM_OBL_RC_ACT: 2147483648 is outside [-, -]"),
        ("COM_RCL_EXCEPT", 1.5, "COM_RCL_EXCEPT: 1.5 must be an integer"),
        ("COM_DISARM_PRFLT", math.inf, "not finite"),
        ("COM_RCL_EXCPT", 1, "unknown parameter 'COM_RCL_EXCPT'; did you mean 'COM_RCL_EXCEPT'"),
    ]:
        with pytest.raises(ParamError, match=message.replace("[", r"\[")):
            ps.set(name, value)
    assert ps["COM_RCL_EXCEPT"] == 4 and ps["GF_PREDICT"] == 1  # refused: unchanged


def test_float_bounds_are_checked_in_float32_as_the_value_travels():
    f32 = 0.6000000238418579  # 0.6 after MAVLink's float32
    ps = ParamSet()
    assert ps.set("MC_PITCHRATE_P", f32) == f32  # honoured, max 0.6
    assert ps.set("EKF2_ABL_LIM", 0.8000000119209290) > 0.8  # stored, max 0.8
    with pytest.raises(ParamError, match="outside"):
        ps.set("MC_PITCHRATE_P", 0.6001)
