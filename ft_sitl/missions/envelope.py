"""Capability envelopes: success against the kinodynamic indicators across aggressiveness
levels, with the vehicle's size held fixed (issue 44; docs/scoring.md, "Capability
envelopes").

The catalog's platforms confound size with agility (small platforms are the agile ones),
so the paper's Q2 asked of the catalog alone answers with size. This module reads the
rows of a campaign that has the aggressiveness axis (:mod:`ft_sitl.missions.
aggressiveness`; column ``aggressiveness``) and, where it flew them, the controlled
platform series (:mod:`ft_sitl.physics.series`: one body, one indicator varied), and
gives:

* :func:`size_controlled_fits` -- per algorithm and level, a logistic regression of
  success on log TWR_max, log alpha_xy,max and the half span (each per standard
  deviation over the rows fitted) with the scenario family as fixed effects, errors
  clustered by platform (a platform's trials share its vehicle). Over the catalog the
  half span is in the model; over a series it is constant within a body, which enters
  as a fixed effect instead, so size cannot confound there.
* :func:`dose_response` -- success per series member with Wilson intervals, against the
  indicator its series varies, per algorithm, family, level and body.
* :func:`envelope_thresholds` -- per algorithm, family, level and series: the smallest
  indicator value from which every stronger member of the series stays within
  ``tolerance`` (10 points) of the series' best success, with a bootstrap interval
  (trials resampled within each member).
* :func:`level_tolerance` -- per catalog platform and algorithm: the highest level up to
  which the platform keeps ``keep`` (80 %) of its success at the gentlest level flown.
* :func:`row_metrics` -- per row: the peak tilt against the tilt at which full thrust
  still holds altitude (``acos(1 / TWR_max)``), and the time to the goal against a
  time-optimal bound (:func:`time_bound_s`).

Degenerate inputs never raise: a fit that cannot be made says why in ``note``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable

import numpy as np
import pandas as pd

from ft_sitl.missions.aggressiveness import LEVELS
from ft_sitl.missions.regression import footprints, separated
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.scoring import wilson_interval
from ft_sitl.missions.spec import TrialSpec, flight_budget, platform_for
from ft_sitl.physics.series import SERIES_CATEGORY
from ft_sitl.scenarios.difficulty import (
    FlightBudget,
    cached_difficulty,
    flight_time_s,
    simplify,
)

#: the row column that names a trial's aggressiveness level ("" without the axis)
LEVEL_COLUMN = "aggressiveness"
#: a series member's name: ``series-<base>-twr<TWR>`` or ``series-<base>-axy<alpha_xy>``
SERIES_NAME = re.compile(r"^series-(?P<base>.+)-(?P<kind>twr|axy)(?P<value>[0-9.]+)$")
#: what each series kind varies: the row column and how it is printed
KIND_COLUMN = {"twr": "twr_max", "axy": "alpha_xy_max"}
KIND_LABEL = {"twr": "TWR_max", "axy": "alpha_xy,max (rad/s^2)"}
#: the terms of the size-controlled model, each entered per standard deviation
TERMS = (("log_twr", "log TWR_max"), ("log_alpha_xy", "log alpha_xy,max"),
         ("half_span", "half span"))
#: fewest rows of each outcome (successes, failures) per coefficient to attempt a fit
MIN_EVENTS_PER_TERM = 5
TOLERANCE = 0.10
KEEP = 0.80
N_BOOT = 1000


def level_order(levels) -> list[str]:
    """The levels present, gentlest first: declared levels in their declared order, then
    any others by name."""
    present = [lv for lv in pd.unique(pd.Series(list(levels), dtype=object)) if lv]
    declared = [name for name in LEVELS if name in present]
    return declared + sorted(lv for lv in present if lv not in LEVELS)


def with_levels(df: pd.DataFrame) -> pd.DataFrame:
    """The rows with a level: their own, or ``paper`` for rows flown without the axis
    at the paper level's limits (the protocol's defaults). Rows of other limits without a
    level are left out: their level is not known."""
    out = df.copy()
    lv = out[LEVEL_COLUMN].fillna("").astype(str) if LEVEL_COLUMN in out else \
        pd.Series("", index=out.index)
    paper = LEVELS["paper"]
    if {"speed_limit_m_s", "acc_limit_m_s2"} <= set(out.columns):
        at_paper = (np.isclose(out["speed_limit_m_s"], paper.max_speed_m_s)
                    & np.isclose(out["acc_limit_m_s2"], paper.max_acc_m_s2))
    else:
        at_paper = pd.Series(False, index=out.index)
    lv = lv.where(lv != "", np.where(at_paper, "paper", ""))
    out[LEVEL_COLUMN] = lv
    return out[out[LEVEL_COLUMN] != ""]


def of_protocols(df: pd.DataFrame, versions: dict[str, int]) -> pd.DataFrame:
    """The rows with each algorithm named in ``versions`` kept only where flown under that
    protocol version (the others' rows as they are): how a study whose campaigns began
    under one version takes one navigator's rows from a later one (docs/results/envelope:
    EGO from protocol 11) without mixing two versions of it in one fit. ValueError names
    an algorithm with no row of its version."""
    keep = pd.Series(True, index=df.index)
    algo = df["algorithm"].astype(str)
    for name, version in versions.items():
        mine = algo == name
        chosen = mine & (df["protocol_version"] == version)
        if not chosen.any():
            flown = sorted(int(v) for v in pd.unique(df.loc[mine, "protocol_version"]))
            raise ValueError(f"no {name} rows of protocol {version} (its rows: protocols "
                             f"{flown or 'none'})")
        keep &= ~mine | chosen
    return df[keep]


def series_members(df: pd.DataFrame) -> pd.DataFrame:
    """The series rows with their series: ``base`` (the base body's name without
    spaces), ``kind`` (twr or axy) and ``value`` (the varied indicator's value)."""
    cat = df["platform_category"].astype(str) if "platform_category" in df else \
        pd.Series("", index=df.index)
    rows = df[cat == SERIES_CATEGORY].copy()
    parts = rows["platform"].astype(str).str.extract(SERIES_NAME)
    rows["base"], rows["kind"] = parts["base"], parts["kind"]
    rows = rows[rows["kind"].notna()]
    rows["value"] = [float(r[KIND_COLUMN[k]]) for k, (_, r) in
                     zip(rows["kind"], rows.iterrows(), strict=True)]
    return rows


# --------------------------------------------------------------------- the regression


def _design(g: pd.DataFrame, fixed: list[str]) -> tuple[pd.DataFrame, list[str]]:
    """The standardised terms (constant ones dropped; the half span too when the body is
    a fixed effect, which holds it) and the fixed-effect dummies."""
    x = pd.DataFrame(index=g.index)
    raw = {"log_twr": np.log(g["twr_max"].astype(float)),
           "log_alpha_xy": np.log(g["alpha_xy_max"].astype(float)),
           "half_span": g["half_span_m"].astype(float)}
    kept = []
    for term, _ in TERMS:
        if term == "half_span" and "base" in fixed:
            continue
        v = raw[term]
        sd = float(v.std(ddof=0))
        if sd > 1e-12 * max(1.0, abs(float(v.mean()))):
            x[term] = (v - v.mean()) / sd
            kept.append(term)
    for col in fixed:
        levels = sorted(g[col].astype(str).unique())
        for name in levels[1:]:
            x[f"{col}={name}"] = (g[col].astype(str) == name).astype(float)
    x.insert(0, "const", 1.0)
    return x, kept


def _fit(g: pd.DataFrame, fixed: list[str]) -> tuple[dict, str]:
    """Coefficients per SD with errors clustered by platform, or why not."""
    # statsmodels: heavy, loaded only when fitting
    import statsmodels.api as sm

    y = g["success"].astype(float).to_numpy()
    # a family (or body) whose trials all succeed or all fail says nothing once it has
    # its own effect, and makes that effect infinite: left out
    for col in fixed:
        rates = g.groupby(col)["success"].transform("mean")
        g = g[(rates > 0) & (rates < 1)]
    if g.empty:
        return {}, "not estimable: every group all successes or all failures"
    y = g["success"].astype(float).to_numpy()
    x, kept = _design(g, fixed)
    if not kept:
        return {}, "not estimable: no variation in the indicators"
    events = min(int(y.sum()), int(len(y) - y.sum()))
    if events < MIN_EVENTS_PER_TERM * x.shape[1]:
        return {}, f"not fitted: {events} of the rarer outcome for {x.shape[1]} coefficients"
    if np.linalg.matrix_rank(x.to_numpy()) < x.shape[1]:
        return {}, "not estimable: the terms are collinear in these rows"
    if separated(x.to_numpy(), y):
        return {}, "not estimable: the outcomes are separated by the terms"
    groups = pd.factorize(g["platform"].astype(str))[0]
    try:
        res = sm.Logit(y, x).fit(disp=0, maxiter=200, cov_type="cluster",
                                 cov_kwds={"groups": groups})
    except (np.linalg.LinAlgError, ValueError) as exc:
        return {}, f"not estimable: {exc}"
    out = {term: (float(res.params[term]), float(res.bse[term]), float(res.pvalues[term]))
           for term in kept}
    return out, f"{len(y)} rows, {len(set(groups))} platforms"


def size_controlled_fits(df: pd.DataFrame) -> pd.DataFrame:
    """Per algorithm, level and sample (``catalog``: the catalog platforms, half span in
    the model; ``series``: the controlled series, the body as a fixed effect): each
    term's log-odds per standard deviation, its clustered standard error and p-value
    (``note`` says the rows and platforms fitted, or why there is no fit)."""
    rows = []
    d = with_levels(df)
    d = d.assign(half_span_m=footprints(d).to_numpy())
    d = d[np.isfinite(d["half_span_m"])]
    cat = d["platform_category"].astype(str)
    samples = {"catalog": (d[cat != SERIES_CATEGORY], ["family"]),
               "series": (series_members(d), ["family", "base"])}
    for sample, (part, fixed) in samples.items():
        for (algo, level), g in part.groupby(["algorithm", LEVEL_COLUMN], sort=True):
            coefs, note = _fit(g, fixed)
            for term, label in TERMS:
                b, se, p = coefs.get(term, (math.nan, math.nan, math.nan))
                rows.append({"algorithm": algo, "level": level, "sample": sample,
                             "term": label, "coef_per_sd": b, "se": se, "p": p,
                             "n": len(g), "note": note})
    out = pd.DataFrame(rows, columns=["algorithm", "level", "sample", "term", "coef_per_sd",
                                      "se", "p", "n", "note"])
    return _sorted_by_level(out, "level")


def _sorted_by_level(out: pd.DataFrame, col: str) -> pd.DataFrame:
    order = {lv: i for i, lv in enumerate(level_order(out[col]))}
    return out.sort_values(by=[col], key=lambda s: s.map(order), kind="stable") \
        .reset_index(drop=True)


# ----------------------------------------------------------------- dose and envelope


def dose_response(df: pd.DataFrame) -> pd.DataFrame:
    """Success of each series member: per algorithm, family, level, body and kind, the
    member's indicator value, trials, successes, rate and 95 % Wilson interval."""
    m = series_members(with_levels(df))
    rows = []
    keys = ["algorithm", "family", LEVEL_COLUMN, "base", "kind", "platform", "value"]
    for key, g in m.groupby(keys, sort=True):
        n, k = len(g), int(g["success"].sum())
        lo, hi = wilson_interval(n, k)
        rows.append(dict(zip(keys, key, strict=True), n=n, successes=k, rate=k / n,
                         lo=lo, hi=hi))
    out = pd.DataFrame(rows, columns=[*keys, "n", "successes", "rate", "lo", "hi"])
    return _sorted_by_level(out.rename(columns={LEVEL_COLUMN: "level"}), "level")


def threshold(values: np.ndarray, rates: np.ndarray, tolerance: float = TOLERANCE) -> float:
    """The smallest value from which every member at or above it succeeds within
    ``tolerance`` of the best member (``values`` ascending; NaN: no members, or the
    strongest member itself falls short, so no value has only good members above it)."""
    if not len(values):
        return math.nan
    ok = rates >= rates.max() - tolerance - 1e-12
    # the lowest index from which all are ok
    bad = np.flatnonzero(~ok)
    first = bad[-1] + 1 if len(bad) else 0
    return float(values[first]) if first < len(values) else math.nan


def envelope_thresholds(df: pd.DataFrame, *, tolerance: float = TOLERANCE,
                        n_boot: int = N_BOOT, seed: int = 0) -> pd.DataFrame:
    """Per algorithm, family, level, body and kind: the series' threshold
    (:func:`threshold`), its 95 % bootstrap interval (each member's trials resampled
    with replacement, ``n_boot`` times, seeded; over the resamples that have one, their
    share in ``boot_found``), the best member's rate and the members counted."""
    m = series_members(with_levels(df))
    rng = np.random.default_rng(seed)
    rows = []
    keys = ["algorithm", "family", LEVEL_COLUMN, "base", "kind"]
    for key, g in m.groupby(keys, sort=True):
        members = sorted(g.groupby("value")["success"], key=lambda kv: kv[0])
        values = np.array([v for v, _ in members])
        outcomes = [s.astype(float).to_numpy() for _, s in members]
        rates = np.array([o.mean() for o in outcomes])
        est = threshold(values, rates, tolerance)
        boot = np.empty(n_boot)
        for b in range(n_boot):
            r = np.array([rng.choice(o, size=len(o)).mean() for o in outcomes])
            boot[b] = threshold(values, r, tolerance)
        found = boot[np.isfinite(boot)]
        lo, hi = (np.percentile(found, [2.5, 97.5]) if len(found) else (math.nan, math.nan))
        rows.append(dict(zip(keys, key, strict=True), threshold=est, lo=float(lo),
                         hi=float(hi), boot_found=len(found) / n_boot if n_boot else math.nan,
                         best_rate=float(rates.max()), members=len(values),
                         lowest=float(values[0]), highest=float(values[-1])))
    cols = [*keys, "threshold", "lo", "hi", "boot_found", "best_rate", "members", "lowest",
            "highest"]
    out = pd.DataFrame(rows, columns=cols).rename(columns={LEVEL_COLUMN: "level"})
    return _sorted_by_level(out, "level")


def level_tolerance(df: pd.DataFrame, *, keep: float = KEEP) -> pd.DataFrame:
    """Per catalog platform and algorithm: success at each level flown, and the highest
    level up to which every level keeps ``keep`` of the success at the gentlest level
    flown (empty when the gentlest level has no success to keep)."""
    d = with_levels(df)
    d = d[d["platform_category"].astype(str) != SERIES_CATEGORY]
    order = level_order(d[LEVEL_COLUMN])
    rows = []
    for (algo, plat), g in d.groupby(["algorithm", "platform"], sort=True):
        rates = g.groupby(LEVEL_COLUMN)["success"].mean()
        flown = [lv for lv in order if lv in rates.index]
        base = float(rates[flown[0]])
        highest = ""
        if base > 0:
            for lv in flown:
                if rates[lv] < keep * base - 1e-12:
                    break
                highest = lv
        rows.append({"algorithm": algo, "platform": plat,
                     "twr_max": float(g["twr_max"].iloc[0]),
                     "alpha_xy_max": float(g["alpha_xy_max"].iloc[0]),
                     "gentlest": flown[0], "gentlest_rate": base, "highest_kept": highest,
                     **{f"rate_{lv}": float(rates[lv]) for lv in flown}})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------------ row metrics


def hover_tilt_deg(twr_max) -> np.ndarray:
    """The tilt (deg) at which full thrust still holds altitude: acos(1 / TWR_max)."""
    twr = np.asarray(twr_max, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.degrees(np.arccos(np.clip(1.0 / twr, -1.0, 1.0)))


def max_horizontal_acc_m_s2(twr_max) -> np.ndarray:
    """The horizontal acceleration full thrust gives while holding altitude:
    g sqrt(TWR_max^2 - 1) (0 for TWR_max <= 1)."""
    twr = np.asarray(twr_max, dtype=float)
    return 9.80665 * np.sqrt(np.maximum(twr * twr - 1.0, 0.0))


def time_bound_s(path_time: Callable[[float, float], float], speed_m_s: float,
                 acc_m_s2: float, twr_max: float) -> float:
    """The time-optimal bound of one row: ``path_time(speed, acc)`` (the scenario's
    shortest path for the platform's body, timed by
    :func:`ft_sitl.scenarios.difficulty.flight_time_s`) under the level's speed cap and
    the lesser of the level's acceleration limit and what the platform can give."""
    acc = min(float(acc_m_s2), float(max_horizontal_acc_m_s2(twr_max)))
    if not acc > 0:
        return math.inf
    return float(path_time(float(speed_m_s), acc))


def time_bounds(df: pd.DataFrame, cache_dir=None) -> pd.Series:
    """Each row's time-optimal bound (s; :func:`time_bound_s`): the shortest path of its
    scenario for its platform's body (the difficulty measure's, computed once per scenario
    configuration and body, kept in ``cache_dir`` when given: 0.1-5 s each), re-timed
    under the row's speed cap and acceleration (its level's, the lesser of it and the
    platform's). NaN where the spec cannot be read or no path was found."""
    paths: dict = {}
    out = np.full(len(df), math.nan)
    budget = flight_budget()
    for i, (spec_text, speed, acc, twr) in enumerate(zip(
            df["spec"], df["speed_limit_m_s"], df["acc_limit_m_s2"], df["twr_max"],
            strict=True)):
        try:
            spec = TrialSpec.from_dict(json.loads(spec_text))
            platform = platform_for(spec)
        except (TypeError, ValueError, KeyError):
            continue
        key = (spec.family, spec.scenario_index, spec.scenario_seed, spec.scenario_version,
               spec.scenario_file, repr(platform.body()))
        if key not in paths:
            found = cached_difficulty(RESOURCES.scenario(spec), platform, budget, cache_dir)
            paths[key] = simplify(np.asarray(found.path)) if found.path else None
        path = paths[key]
        if path is None or not (math.isfinite(speed) and math.isfinite(acc)):
            continue
        out[i] = time_bound_s(lambda v, a, p=path: flight_time_s(
            p, FlightBudget(v, a, budget.time_s)), speed, acc, twr)
    return pd.Series(out, index=df.index, name="time_bound_s")


def row_metrics(df: pd.DataFrame, bounds: pd.Series | None = None) -> pd.DataFrame:
    """Per row: ``tilt_ratio`` (peak tilt over :func:`hover_tilt_deg`: above 1 the
    vehicle tilted beyond where it can hold altitude), ``saturation_fraction`` (the time
    at saturation, as flown) and, given ``bounds`` (each row's time-optimal bound, s),
    ``time_ratio`` (time to the goal over it; NaN for rows that did not reach it)."""
    out = pd.DataFrame(index=df.index)
    out["hover_tilt_deg"] = hover_tilt_deg(df["twr_max"])
    out["tilt_ratio"] = df["max_tilt_deg"].astype(float) / out["hover_tilt_deg"]
    out["saturation_fraction"] = df["saturation_fraction"].astype(float)
    if bounds is not None:
        out["time_bound_s"] = bounds.astype(float)
        out["time_ratio"] = df["time_to_goal_s"].astype(float) / out["time_bound_s"]
    return out
