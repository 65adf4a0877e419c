"""Controlled platform series: a catalog body with one indicator changed at a time.

In the catalog, size and kinodynamics move together (small platforms are also the agile
ones), so success against an indicator mixes the indicator with the body. A series keeps
one base platform's body, mass and geometry exactly (arm length, propeller, collision
body, drag, motor lag) and moves one indicator (docs/platforms.md, "Controlled platform
series"):

* **TWR series** (:func:`with_twr`): stronger motors spin the same propeller faster,
  ω_max and the idle speed x sqrt(k) for TWR_max x k. Roll, pitch and yaw torque all grow
  by k as well (eqs. 4/5: they are proportional to T_max - T_min), so on their own the
  motors would raise α_xy and α_z by k. The mass distribution takes that back: the whole
  inertia tensor grows by k (mass moved outward, J_zz/J_xx unchanged), so α_xy,max and
  α_z,max stay the base's exactly.
* **α series** (:func:`with_alpha_xy`): same motors, the inertia tensor scaled by
  α_base / α (mass moved inward or outward). TWR_max stays the base's; α_z,max moves in
  proportion with α_xy,max (J_zz/J_xx is held): holding it too would take J_zz/J_xx and
  the propeller's torque ratio beyond the synthesis rules' ranges (a factor of about 9
  between them, against the 26 of the catalog's α_xy range).

The mass distribution has one physical ceiling: the normalised roll inertia
γ = J_xx / (m d²) is 0.5 when all the mass sits at the rotor hubs, and the synthesis
rules stop at :data:`ft_sitl.physics.synthesis.GAMMA_MAX` (0.45). That bounds each body:
holding α while raising TWR by k raises γ by k, and lowering α by k raises γ by k. A
request beyond it is refused with the allowed range (:func:`twr_range`,
:func:`alpha_xy_range`). No floor is imposed, as in the synthesis (the paper's virtual
set has γ down to 0.065; docs/platforms.md lists every member's γ).

The shipped series (:func:`build_series`) are flown by name like the catalog
(:data:`SERIES_CATEGORY`); :func:`ft_sitl.physics.catalog.series` loads them through the
user-file path, so they pass exactly the checks a user platform file passes.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ft_sitl.physics.platform import Platform, PlatformError
from ft_sitl.physics.synthesis import GAMMA_MAX, TWR_RANGE

#: the category of every shipped series platform (campaign files select it by name)
SERIES_CATEGORY = "series"
#: the base platforms: a small, a middle and a large catalog body (half span 0.19, 0.32,
#: 0.45 m), the smallest, a middle and the largest whose α can be held over the TWR range
SERIES_BASES = ("0.55kg-UAV 1", "1.00kg-SunnySky", "5.00kg-UAV 16")
#: TWR_max of the TWR series' members
TWR_LEVELS = (1.2, 1.5, 2.0, 3.0, 4.0, 6.0)
#: how many members an α series has (log-spaced over the catalog's α_xy range)
ALPHA_COUNT = 5
#: the upper end of the α_xy a series may request (the synthesis' indicator range)
ALPHA_XY_MAX_RAD_S2 = 20000.0
#: relative slack on γ's ceiling (a member at the base's own value sits on it to round-off)
_GAMMA_SLACK = 1e-9


def slug(name: str) -> str:
    """A platform name without spaces (``5.00kg-UAV 16`` -> ``5.00kg-UAV16``)."""
    return name.replace(" ", "")


def _label(value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals, or all it needs if it has more."""
    text = f"{value:.{digits}f}"
    return text if float(text) == value else repr(float(value))


def twr_name(base: Platform, twr: float) -> str:
    """``series-<base>-twr<TWR_max>``, e.g. ``series-5.00kg-UAV16-twr2.0``."""
    return f"series-{slug(base.name)}-twr{_label(twr, 1)}"


def alpha_name(base: Platform, alpha_xy: float) -> str:
    """``series-<base>-axy<alpha_xy>``, e.g. ``series-5.00kg-UAV16-axy348``."""
    return f"series-{slug(base.name)}-axy{_label(alpha_xy, 0)}"


def gamma(p: Platform) -> float:
    """The normalised roll inertia J_xx / (m d²): 0.5 with all the mass at the hubs."""
    return p.inertia_kg_m2[0] / (p.mass_kg * p.arm_length_m**2)


def twr_range(base: Platform) -> tuple[float, float]:
    """The TWR_max a TWR series of ``base`` may have: from the validation's 1.05 to where
    holding its α puts γ at the ceiling (and at most the synthesis' 8)."""
    return _twr_bounds(base)[0][0], _twr_bounds(base)[1][0]


def alpha_xy_range(base: Platform) -> tuple[float, float]:
    """The α_xy,max an α series of ``base`` may have: from where γ reaches the ceiling up
    to the synthesis' 20000 rad/s²."""
    return _alpha_bounds(base)[0][0], _alpha_bounds(base)[1][0]


_CEILING = f"more inertia than Jxx/(m d^2) = {GAMMA_MAX}, the synthesis' ceiling"


def _twr_bounds(base: Platform):
    """((lowest TWR_max, why), (highest, why)) for a TWR series of ``base``."""
    ind = base.indicators()
    by_inertia = float(ind.twr_max) * GAMMA_MAX / gamma(base)
    low = (TWR_RANGE[0], "hovering with a control margin needs 1.05")
    if by_inertia < TWR_RANGE[1]:
        return low, (by_inertia, f"holding alpha_xy {float(ind.alpha_xy_max_rad_s2):.4g} "
                                 f"rad/s^2 above it needs {_CEILING}")
    return low, (TWR_RANGE[1], "above it the hover thrust falls to PX4's MPC_THR_MIN")


def _alpha_bounds(base: Platform):
    """((lowest alpha_xy,max, why), (highest, why)) for an α series of ``base``."""
    ind = base.indicators()
    return ((float(ind.alpha_xy_max_rad_s2) * gamma(base) / GAMMA_MAX,
             f"at TWR_max {float(ind.twr_max):.4g} below it needs {_CEILING}"),
            (ALPHA_XY_MAX_RAD_S2, "the synthesis' indicator range"))


def _check(base: Platform, key: str, value: float, bounds, unit: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise PlatformError(f"series of {base.name!r}: {key}: {value!r} is not a finite number")
    (lo, lo_why), (hi, hi_why) = bounds
    if not lo * (1 - _GAMMA_SLACK) <= value <= hi * (1 + _GAMMA_SLACK):
        raise PlatformError(
            f"series of {base.name!r}: {key}: {value:g}{unit} is outside the allowed range "
            f"[{lo:.6g}, {hi:.6g}]{unit} for this body ({lo_why if value < lo else hi_why})")


def with_twr(base: Platform, twr: float, name: str | None = None,
             category: str = SERIES_CATEGORY) -> Platform:
    """``base`` with stronger (or weaker) motors giving TWR_max ``twr``, its α held by the
    inertia (module docstring). Not yet validated: the catalog loads it as a file entry."""
    _check(base, "twr_max", twr, _twr_bounds(base), "")
    k = twr / float(base.indicators().twr_max)
    root = math.sqrt(k)
    return replace(
        base,
        name=name or twr_name(base, twr),
        category=category,
        inertia_kg_m2=tuple(j * k for j in base.inertia_kg_m2),
        rotor_speed_min_rad_s=base.rotor_speed_min_rad_s * root,
        rotor_speed_max_rad_s=base.rotor_speed_max_rad_s * root,
        source=(f"controlled series (ft_sitl.physics.series): {base.name} with motors for "
                f"TWR_max {twr:g}, inertia x{k:.4f} to hold its alpha_xy and alpha_z"),
    )


def with_alpha_xy(base: Platform, alpha_xy: float, name: str | None = None,
                  category: str = SERIES_CATEGORY) -> Platform:
    """``base`` with its mass redistributed for α_xy,max ``alpha_xy`` (the inertia tensor
    scaled, so α_z,max moves in proportion); TWR_max and everything else its own."""
    _check(base, "alpha_xy_max_rad_s2", alpha_xy, _alpha_bounds(base), " rad/s^2")
    s = float(base.indicators().alpha_xy_max_rad_s2) / alpha_xy
    return replace(
        base,
        name=name or alpha_name(base, alpha_xy),
        category=category,
        inertia_kg_m2=tuple(j * s for j in base.inertia_kg_m2),
        source=(f"controlled series (ft_sitl.physics.series): {base.name} with its mass "
                f"redistributed for alpha_xy {alpha_xy:g} rad/s^2 (inertia x{s:.4f})"),
    )


def alpha_levels(base: Platform, catalog_alphas: list[float]) -> tuple[float, ...]:
    """:data:`ALPHA_COUNT` α_xy values log-spaced over the catalog's range, cut to what the
    body allows, rounded to whole rad/s² inside it."""
    lo = math.ceil(max(min(catalog_alphas), alpha_xy_range(base)[0]))
    hi = math.floor(max(catalog_alphas))
    ratio = hi / lo
    return tuple(float(round(lo * ratio ** (i / (ALPHA_COUNT - 1))))
                 for i in range(ALPHA_COUNT))


def build_series(catalog: dict[str, Platform]) -> list[Platform]:
    """The shipped series, unvalidated: for each base of :data:`SERIES_BASES`, its TWR
    series (:data:`TWR_LEVELS`), then its α series (:func:`alpha_levels`)."""
    alphas = [float(p.indicators().alpha_xy_max_rad_s2) for p in catalog.values()]
    out = []
    for name in SERIES_BASES:
        base = catalog[name]
        out.extend(with_twr(base, t) for t in TWR_LEVELS)
        out.extend(with_alpha_xy(base, a) for a in alpha_levels(base, alphas))
    return out
