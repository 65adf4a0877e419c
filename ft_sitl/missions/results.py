"""The results table: one row per trial, the same columns everywhere.

A campaign writes each finished trial as one JSON object per line (``trials.jsonl``, see
``ft_sitl.missions.store``); :func:`to_frame` turns such rows into the tidy pandas table
that scoring, reports and users read (Parquet ``trials.parquet``, CSV on request).

Column meanings (units in the name; NaN where a value does not apply):

identity
    ``trial_id`` (stable key of the trial's spec), ``campaign``, ``algorithm`` (navigator
    name), ``algorithm_params`` (JSON), ``platform``, ``platform_category`` (real /
    virtual / user), ``mass_kg``, ``twr_max``, ``alpha_xy_max``, ``alpha_z_max`` (rad/s^2),
    ``family``, ``scenario_category`` (classic / theoretical / user), ``scenario_index``,
    ``scenario_seed``, ``scenario`` (name), ``trial`` (0-based repetition), ``seed``.
axes (the trial's wind, ft_sitl.physics.wind, and PX4 parameters; calm air and the
default parameters for rows written before they existed)
    ``wind_speed_m_s`` (mean), ``turbulence`` (Dryden intensity), ``gust_m_s``, ``wind``
    (every setting that differs from the defaults, as JSON; "" in calm air); ``params``
    (the PX4 parameters the trial set, as JSON; "" for the defaults); ``actuators``
    (imperfect actuators, ft_sitl.physics.actuators, as JSON; "" as built);
    ``perception`` (the navigator's latency, state noise and dropped frames,
    ft_sitl.missions.perception, as JSON; "" ideal); ``estimator`` (the flight
    controller's noisy, biased, late estimate, ft_sitl.autopilot.estimator, as JSON; ""
    the truth); ``failures`` (failures injected during the trial, autopilot.failures, as
    JSON; "" none); ``mover_count`` (moving obstacles placed, scenarios.movers),
    ``mover_speed_m_s`` (their speed), ``movers`` (their non-default settings as JSON; 0,
    0 and "" in a static world); ``fence`` (the geofence the flight controller kept,
    spec.fence_setting, as JSON; "" none); ``aggressiveness`` (the level's name,
    missions.aggressiveness; "" when the campaign has no aggressiveness axis),
    ``speed_limit_m_s`` and ``acc_limit_m_s2`` (the speed cap and the acceleration limit
    the trial flew under, its spec's limits: filled in from the spec for rows written
    before the columns existed; NaN acceleration before protocol 3).
outcome
    ``success`` (bool), ``reason`` (an :class:`Outcome` value; ``mover_collision`` is a
    collision with a moving obstacle), ``detail`` (what was hit,
    which bound, the navigator's exception ...).
metrics (navigation phase)
    ``time_to_goal_s`` (first entry into the goal sphere, from navigation start),
    ``nav_time_s``, ``path_length_m``, ``mean_speed_m_s``, ``max_speed_m_s``,
    ``min_clearance_m`` (obstacle clearance of the collision sphere, sampled),
    ``max_tilt_deg``, ``tracking_rms_m`` (the time-weighted RMS distance between the
    flown position and the flight controller's position setpoint, over the axes it
    commands; empty for rows written before it was recorded), ``saturation_fraction``
    (physics steps with any rotor at a limit),
    ``energy_j`` (motor mechanical energy), ``replans``, ``planner_time_s`` (navigator
    compute, wall clock), ``planner_calls``, ``fence_breaches`` (how often the vehicle
    left the inside of its geofence, as the flight controller counts breaches; empty for
    rows written before it was recorded), ``fence_breach_s`` (the first breach, from
    navigation start; NaN if none).
run
    ``sim_time_s``, ``wall_time_s``, ``code_version``, ``software`` (JSON: ft_sitl's
    version and code digest, Python's and the numeric libraries' versions,
    ft_sitl.provenance.software; empty for rows written before it was recorded),
    ``protocol_version`` (the trial
    protocol's version, ft_sitl.missions.spec.PROTOCOLS; 1 for rows written before it was
    recorded), ``gains`` (the controller-gain mode the trial flew, "bandwidth" or "px4":
    FT_GAIN_MODE 0 or 1; "bandwidth" for rows written before it was recorded),
    ``scenario_version`` (the version of the family's generator that built the scenario,
    scenarios.families.Family.versions; 1 for rows written before it was recorded, empty
    for a scenario file),
    ``finished_utc``, ``spec`` (the full trial spec as JSON: enough to rerun the
    trial alone).
"""

from __future__ import annotations

import json
import math
from enum import StrEnum

from ft_sitl.autopilot.params import DEFAULT_GAINS


class Outcome(StrEnum):
    """How a trial ended: the ``reason`` column (the FLYINGTRUST protocol's exit reasons,
    docs/missions.md), in the order reports list them."""

    SUCCESS = "success"
    COLLISION = "collision"
    MOVER_COLLISION = "mover_collision"
    OUT_OF_BOUNDS = "out_of_bounds"
    #: the flight controller took the vehicle from the navigator on a geofence breach
    #: (GF_ACTION hold, return, terminate or land; ft-sitl's, not the paper's)
    GEOFENCE = "geofence"
    TIMEOUT = "timeout"
    UNSTABLE = "unstable"
    LOSS_OF_CONTROL = "loss_of_control"
    NAVIGATOR_ERROR = "navigator_error"


#: the outcome values in report order (a view of :class:`Outcome`)
REASONS: tuple[str, ...] = tuple(o.value for o in Outcome)


class RowError(ValueError):
    """A results row whose outcome columns are not what the protocol writes."""


def check_outcome(row: dict) -> None:
    """Raise :class:`RowError` unless ``row["reason"]`` is an :class:`Outcome` value and
    ``row["success"]`` says whether it is SUCCESS (rows are checked where they are written
    and where they are read)."""
    reason = row.get("reason")
    if not isinstance(reason, str) or reason not in REASONS:
        raise RowError(f"trial {row.get('trial_id', '?')}: reason {reason!r} is not one of "
                       f"{', '.join(REASONS)}")
    success = row.get("success")
    if isinstance(success, float) and math.isnan(success):
        success = None
    if success is None or bool(success) != (reason == Outcome.SUCCESS):
        raise RowError(f"trial {row.get('trial_id', '?')}: success {success!r} does not "
                       f"match reason {reason!r}")

IDENTITY = ("trial_id", "campaign", "algorithm", "algorithm_params", "platform",
            "platform_category", "mass_kg", "twr_max", "alpha_xy_max", "alpha_z_max",
            "family", "scenario_category", "scenario_index", "scenario_seed", "scenario",
            "trial", "seed")
AXES = ("wind_speed_m_s", "turbulence", "gust_m_s", "wind", "params", "actuators",
        "perception", "estimator", "failures", "mover_count", "mover_speed_m_s", "movers",
        "fence", "aggressiveness", "speed_limit_m_s", "acc_limit_m_s2")
OUTCOME = ("success", "reason", "detail")
METRICS = ("time_to_goal_s", "nav_time_s", "path_length_m", "mean_speed_m_s",
           "max_speed_m_s", "min_clearance_m", "max_tilt_deg", "tracking_rms_m",
           "saturation_fraction", "energy_j", "replans", "planner_time_s", "planner_calls",
           "fence_breaches", "fence_breach_s")
RUN = ("sim_time_s", "wall_time_s", "code_version", "software", "protocol_version", "gains",
       "scenario_version", "finished_utc", "spec")
COLUMNS = IDENTITY + AXES + OUTCOME + METRICS + RUN

CATEGORICAL = ("campaign", "algorithm", "platform", "platform_category", "family",
               "scenario_category", "scenario", "reason", "gains", "turbulence",
               "aggressiveness")
INTEGER = ("scenario_index", "scenario_seed", "trial", "seed", "replans", "planner_calls",
           "fence_breaches", "protocol_version", "scenario_version", "mover_count")
FLOAT = ("mass_kg", "twr_max", "alpha_xy_max", "alpha_z_max", "wind_speed_m_s",
         "gust_m_s", "mover_speed_m_s", "speed_limit_m_s", "acc_limit_m_s2") + tuple(
             m for m in METRICS if m not in INTEGER) + ("sim_time_s", "wall_time_s")


def to_frame(rows):
    """The tidy table of trial rows (dicts with :data:`COLUMNS`), typed: categoricals
    for the grouping columns (``reason`` with every category of :data:`REASONS`).
    :class:`RowError` for a row whose outcome is not one the protocol writes."""
    import pandas as pd  # heavy: kept off the import path of modules needing only Outcome

    rows = list(rows)
    for row in rows:
        check_outcome(row)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    for c in INTEGER:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
    # rows written before the version was recorded flew protocol 1
    df["protocol_version"] = df["protocol_version"].fillna(1)
    # ... and were built by their family's first generator (a scenario file has none)
    df["scenario_version"] = df["scenario_version"].mask(
        df["scenario_version"].isna() & ~df["spec"].astype(str).str.contains(
            '"scenario_file":"', regex=False), 1)
    df["gains"] = df["gains"].astype(object).fillna(DEFAULT_GAINS)  # (likewise: the default)
    # ... and in calm air
    df["wind_speed_m_s"] = df["wind_speed_m_s"].fillna(0.0)
    df["gust_m_s"] = df["gust_m_s"].fillna(0.0)
    df["turbulence"] = df["turbulence"].astype(object).fillna("none")
    df["wind"] = df["wind"].astype(object).fillna("")
    df["params"] = df["params"].astype(object).fillna("")
    df["actuators"] = df["actuators"].astype(object).fillna("")
    df["perception"] = df["perception"].astype(object).fillna("")
    df["estimator"] = df["estimator"].astype(object).fillna("")
    df["failures"] = df["failures"].astype(object).fillna("")
    df["fence"] = df["fence"].astype(object).fillna("")
    # ... and in a static world
    df["mover_count"] = df["mover_count"].fillna(0)
    df["mover_speed_m_s"] = df["mover_speed_m_s"].fillna(0.0)
    df["movers"] = df["movers"].astype(object).fillna("")
    # ... and without an aggressiveness axis, under the limits their specs hold
    df["aggressiveness"] = df["aggressiveness"].astype(object).fillna("")
    for c in ("speed_limit_m_s", "acc_limit_m_s2"):
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    old = df["speed_limit_m_s"].isna()
    if old.any():
        limits = [spec_limits(s) for s in df.loc[old, "spec"]]
        df.loc[old, "speed_limit_m_s"] = [sp for sp, _ in limits]
        df.loc[old, "acc_limit_m_s2"] = [acc for _, acc in limits]
    for c in FLOAT:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    df["success"] = df["success"].astype(bool)
    for c in CATEGORICAL:
        if c == "reason":
            df[c] = pd.Categorical(df[c], categories=list(REASONS))
        else:
            df[c] = df[c].astype("category")
    return df


def spec_limits(spec) -> tuple[float, float]:
    """(speed cap m/s, acceleration limit m/s^2) of a row's ``spec`` column (the spec's
    JSON); NaN where the spec sets none (the acceleration before protocol 3) or the row
    has no readable spec."""
    try:
        limits = json.loads(spec)["limits"]
    except (TypeError, ValueError, KeyError):
        return math.nan, math.nan
    if not isinstance(limits, dict):
        return math.nan, math.nan
    return tuple(float(v) if isinstance(v, (int, float)) and not isinstance(v, bool)
                 else math.nan
                 for v in (limits.get("max_speed_m_s"), limits.get("max_acc_m_s2")))


def rows_from_parquet(path) -> list[dict]:
    """The trial rows of a ``trials.parquet`` table, as :func:`to_frame`'s input holds
    them: plain Python values, NaN where a float does not apply, None for a missing
    integer."""
    import pandas as pd  # as to_frame: pandas only for callers that read tables

    df = pd.read_parquet(path).astype(object)
    return [{k: (None if v is pd.NA else v) for k, v in rec.items()}
            for rec in df.to_dict("records")]

