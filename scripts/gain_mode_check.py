"""Fly every catalog platform under both controller-gain modes (FT_GAIN_MODE 0 and 1) in
the open and measure how well it tracks: what docs/control.md ("Gain modes") and
docs/missions.md (the campaign key ``gains``) report.

Four manoeuvres per platform and mode, each from a settled hover at (0, 0, 2) m, with the
controller's default parameters otherwise (MPC_XY_VEL_MAX 4 m/s, as in a trial):

* ``hover``: hold for 5 s; position RMS error and body-rate RMS over the last 4 s (a limit
  cycle shows as rate RMS well above zero);
* ``step``: a position setpoint 1 m east and 1 m up (the flight controller's own setpoint,
  MPC_ACC_* apply); the overshoot along x, the time to stay within 5 cm, the error after
  10 s, the largest tilt;
* ``dash``: an offboard velocity setpoint of 4 m/s east at constant altitude (offboard:
  only the tilt and thrust limits bound it, as in a trial under protocol 2 on) for 6 s,
  then 0 m/s for 5 s; the time to 90 % of the speed, the speed RMS error and body-rate RMS
  over the last 2 s of the cruise, the altitude's largest deviation, the largest tilt,
  the overshoot of the stop;
* ``yaw``: a 90 deg yaw step at hover; the 90 % rise time, the overshoot, the time to stay
  within 5 deg, the altitude's largest deviation;
* ``yaw_ramp``: the same 90 deg turn as the planners command it (their yaw pursuit turns
  at most pi/2 rad/s: navigation.planners.skeleton.pursue_yaw), a ramp over 1 s streamed at 200 Hz;
  the overshoot and the time to stay within 5 deg, from the start of the ramp;
* ``slalom``: an offboard trajectory (position, velocity and acceleration feed-forward, as
  the planners send) 2 m/s east weaving 1.5 m north and south at 2 rad/s, i.e. 6 m/s^2 of
  lateral acceleration at the peaks (the sweep's aggressive limit), for 10 s; the RMS and
  largest position error over the last 6 s and the largest tilt.

A platform "fails" a manoeuvre when its state goes non-finite, it tilts beyond 60 deg, or it
ends the step more than 5 cm off. Run::

    PYTHONPATH=$PWD .venv/bin/python scripts/gain_mode_check.py --out gain_modes.csv

(about a minute per mode on one core after the first compilation); ``--platforms`` picks
some, ``--modes 1`` one mode.
"""

from __future__ import annotations

import argparse
import math
import sys

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np
import pandas as pd

from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.lockstep import Simulation

HOVER = np.array([0.0, 0.0, 2.0])
REC_HZ = 200.0
DASH_M_S = 4.0
FAIL_TILT_DEG = 60.0
STEP_TOL_M = 0.05


def _tilt_deg(x: np.ndarray) -> np.ndarray:
    """Tilt (body z against world z) of each recorded state, degrees."""
    q = x[:, d.X_QUAT:d.X_QUAT + 4]
    cos_tilt = 1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2)
    return np.degrees(np.arccos(np.clip(cos_tilt, -1.0, 1.0)))


def _yaw(x: np.ndarray) -> np.ndarray:
    q = x[:, d.X_QUAT:d.X_QUAT + 4]
    return np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]),
                      1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))


def _sim(platform, mode: int) -> Simulation:
    sim = Simulation(platform, params=ParamSet({"FT_GAIN_MODE": mode}))
    sim.start_hovering(0, HOVER)
    sim.run(2.0)  # settle the integrators at hover
    return sim


def _run(sim: Simulation, seconds: float) -> np.ndarray:
    return sim.run(seconds, record_hz=REC_HZ).x[:, 0, :]


def _rate_rms(x: np.ndarray) -> float:
    w = x[:, d.X_OMEGA:d.X_OMEGA + 3]
    return float(np.sqrt(np.mean(np.sum(w ** 2, axis=1))))


def _first_time(mask: np.ndarray) -> float:
    k = np.flatnonzero(mask)
    return float(k[0] / REC_HZ) if k.size else math.nan


def _settle_time(err: np.ndarray, tol: float) -> float:
    """Time after which ``err`` stays below ``tol`` (NaN if it never does)."""
    out = np.flatnonzero(err >= tol)
    if not out.size:
        return 0.0
    return float((out[-1] + 1) / REC_HZ) if out[-1] + 1 < err.size else math.nan


def _finite(x: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(x)))


def hover(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    x = _run(sim, 5.0)[int(REC_HZ):]
    err = np.linalg.norm(x[:, d.X_POS:d.X_POS + 3] - HOVER, axis=1)
    return {"hover_pos_rms_mm": 1e3 * float(np.sqrt(np.mean(err ** 2))),
            "hover_rate_rms": _rate_rms(x), "hover_ok": _finite(x)}


def step(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    target = HOVER + [1.0, 0.0, 1.0]
    sim.set_setpoint(0, Setpoint.position(target, yaw=0.0))
    x = _run(sim, 10.0)
    pos = x[:, d.X_POS:d.X_POS + 3]
    err = np.linalg.norm(pos - target, axis=1)
    tilt = _tilt_deg(x)
    final = float(err[-1])
    return {"step_overshoot_m": float(max(0.0, pos[:, 0].max() - target[0])),
            "step_settle_s": _settle_time(err, STEP_TOL_M), "step_final_m": final,
            "step_tilt_deg": float(tilt.max()),
            "step_ok": _finite(x) and final <= STEP_TOL_M and tilt.max() < FAIL_TILT_DEG}


def dash(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    go = Setpoint.trajectory(position=[math.nan, math.nan, HOVER[2]],
                             velocity=[DASH_M_S, 0.0, math.nan], yaw=0.0).offboard()
    sim.set_setpoint(0, go)
    x1 = _run(sim, 6.0)
    stop = Setpoint.trajectory(position=[math.nan, math.nan, HOVER[2]],
                               velocity=[0.0, 0.0, math.nan], yaw=0.0).offboard()
    sim.set_setpoint(0, stop)
    x2 = _run(sim, 5.0)
    x = np.concatenate([x1, x2])
    vx1 = x1[:, d.X_VEL]
    cruise = x1[-int(2 * REC_HZ):]
    v_err = np.linalg.norm(cruise[:, d.X_VEL:d.X_VEL + 3] - [DASH_M_S, 0, 0], axis=1)
    tilt = _tilt_deg(x)
    return {"dash_rise_s": _first_time(vx1 >= 0.9 * DASH_M_S),
            "dash_speed_rms": float(np.sqrt(np.mean(v_err ** 2))),
            "dash_rate_rms": _rate_rms(cruise),
            "dash_alt_dev_m": float(np.abs(x[:, d.X_POS + 2] - HOVER[2]).max()),
            "dash_tilt_deg": float(tilt.max()),
            "dash_stop_overshoot_m_s": float(max(0.0, -x2[:, d.X_VEL].min())),
            "dash_ok": _finite(x) and tilt.max() < FAIL_TILT_DEG}


def yaw(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    sim.set_setpoint(0, Setpoint.position(HOVER, yaw=math.pi / 2))
    x = _run(sim, 8.0)
    psi = np.unwrap(_yaw(x))
    return {"yaw_rise_s": _first_time(psi >= 0.9 * math.pi / 2),
            "yaw_overshoot_deg": float(max(0.0, math.degrees(psi.max() - math.pi / 2))),
            "yaw_settle_s": _settle_time(np.abs(psi - math.pi / 2), math.radians(5.0)),
            "yaw_alt_dev_m": float(np.abs(x[:, d.X_POS + 2] - HOVER[2]).max()),
            "yaw_ok": _finite(x)}


def yaw_ramp(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    n = int(8.0 * REC_HZ)
    psi = np.empty(n)
    for k in range(n):
        sp = min(math.pi / 2, (math.pi / 2) * k / REC_HZ)
        sim.set_setpoint(0, Setpoint.position(HOVER, yaw=sp).offboard())
        sim.run(1.0 / REC_HZ)
        psi[k] = _yaw(sim.x[0][None, :])[0]
    psi = np.unwrap(psi)
    return {"ramp_overshoot_deg": float(max(0.0, math.degrees(psi.max() - math.pi / 2))),
            "ramp_settle_s": _settle_time(np.abs(psi - math.pi / 2), math.radians(5.0)),
            "ramp_ok": bool(np.all(np.isfinite(psi)))}


SLALOM_V, SLALOM_A, SLALOM_W = 2.0, 1.5, 2.0  # m/s east, m amplitude, rad/s


def slalom(platform, mode: int) -> dict:
    sim = _sim(platform, mode)
    n = int(10.0 * REC_HZ)
    err = np.empty(n)
    tilt = np.empty(n)
    ok = True
    for k in range(n):  # the setpoint at REC_HZ, as a planner's trajectory stream
        t = k / REC_HZ
        s, c_ = math.sin(SLALOM_W * t), math.cos(SLALOM_W * t)
        p = HOVER + [SLALOM_V * t, SLALOM_A * s, 0.0]
        v = [SLALOM_V, SLALOM_A * SLALOM_W * c_, 0.0]
        a = [0.0, -SLALOM_A * SLALOM_W ** 2 * s, 0.0]
        sim.set_setpoint(0, Setpoint.position(p, velocity=v, acceleration=a,
                                              yaw=0.0).offboard())
        sim.run(1.0 / REC_HZ)
        x = sim.x[0]
        ok = ok and bool(np.all(np.isfinite(x)))
        err[k] = np.linalg.norm(x[d.X_POS:d.X_POS + 3] - p)
        tilt[k] = _tilt_deg(x[None, :])[0]
    late = err[-int(6 * REC_HZ):]
    return {"slalom_err_rms_m": float(np.sqrt(np.mean(late ** 2))),
            "slalom_err_max_m": float(late.max()), "slalom_tilt_deg": float(tilt.max()),
            "slalom_ok": ok and tilt.max() < FAIL_TILT_DEG}


def check(platform, mode: int) -> dict:
    ind = platform.indicators()
    row = {"platform": platform.name, "category": platform.category, "mode": mode,
           "twr_max": ind.twr_max, "alpha_xy_max": ind.alpha_xy_max_rad_s2,
           "alpha_z_max": ind.alpha_z_max_rad_s2,
           "motor_tau_up_ms": 1e3 * platform.motor_tau_up_s}
    for fn in (hover, step, dash, yaw, yaw_ramp, slalom):
        with np.errstate(all="ignore"):
            row.update(fn(platform, mode))
    row["ok"] = all(row[f"{m}_ok"] for m in ("hover", "step", "dash", "yaw", "ramp", "slalom"))
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="gain_modes.csv", help="CSV of every measurement")
    ap.add_argument("--modes", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--platforms", nargs="+", help="platform names (default: all 36)")
    args = ap.parse_args(argv)
    plats = catalog()
    names = args.platforms or list(plats)
    rows = []
    for mode in args.modes:
        for name in names:
            rows.append(check(plats[name], mode))
            r = rows[-1]
            print(f"mode {mode} {name:28s} ok={r['ok']!s:5} step {r['step_settle_s']:5.2f} s "
                  f"dash rise {r['dash_rise_s']:5.2f} s rate rms {r['dash_rate_rms']:.3f} "
                  f"yaw overshoot {r['yaw_overshoot_deg']:4.1f} deg slalom rms "
                  f"{r['slalom_err_rms_m']:.3f} m", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(args.out, index=False)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
