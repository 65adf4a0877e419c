"""Synthesis of full physical parameters from mass and the three FLYINGTRUST indicators.

The paper (Sec. III-A, Table 1) gives each platform's mass, TWR_max, alpha_xy,max and
alpha_z,max only. :func:`synthesise` builds a physically consistent quadrotor that
reproduces them exactly, by fixed, documented design rules (docs/platforms.md):

1. Arm length from mass, d = 0.15 m * (m / 1 kg)^0.4 (the trend of 250-900 mm wheelbase
   frames over 0.5-5.5 kg), lengthened (at most x1.7) when the normalised roll inertia
   Jxx / (m d^2) would exceed 0.45 (more mass outside the arms than a real frame has).
2. Propeller diameter 1.15 d (adjacent props of an X or + frame clear each other below
   1.41 d), static thrust coefficient C_T = 0.11 (n-based), so c_T = C_T rho D^4 / (4 pi^2).
3. w_max from TWR_max (eq. 2); idle speed 12 % of w_max.
4. Jxx = Jyy = tau_x,max / alpha_xy (eqs. 4/5, 9: opposing rotors at idle).
5. Jzz = 1.75 Jxx (typical of flat quadrotor frames: 1.6-1.9), then c_M/c_T from
   alpha_z. If that ratio falls outside 0.03-0.15 propeller diameters (the range of real
   propellers' torque-to-thrust ratios) Jzz/Jxx moves inside [1.1, 2.0] to bring it back;
   2.0 is the triangle-inequality limit Jzz <= Jxx + Jyy.
6. Motor time constants 12 ms + 7 ms/kg (spin-up), 1.3x that for spin-down; rotor drag
   0.1 kg/s per kg at hover; body drag 0.5 rho Cd A with Cd = 1 and frontal area
   0.02 m^2 (m / 1 kg)^(2/3) (0.05 m^2 from above); collision radius 1.3 d (frame and
   motors; see docs/platforms.md for why not the prop tips).
"""

from __future__ import annotations

import math

import numpy as np

from ft_sitl import G
from ft_sitl.physics.layouts import LAYOUTS, allocation_matrix, get_layout, max_axis_torques
from ft_sitl.physics.platform import Platform, PlatformError, validate

TWR_RANGE = (1.05, 8.0)  # above 8, hover needs less than PX4's MPC_THR_MIN (12 %) of thrust
RHO_AIR = 1.225  # kg/m^3, ISA sea level
ARM_COEFF_M = 0.15
ARM_MASS_EXPONENT = 0.4
GAMMA_MAX = 0.45
ARM_STRETCH_MAX = 1.7
PROP_PER_ARM = 1.15
CT_STATIC = 0.11
IDLE_RATIO = 0.12
JZZ_OVER_JXX = 1.75
JZZ_OVER_JXX_RANGE = (1.1, 2.0)
KAPPA_PER_PROP_RANGE = (0.03, 0.15)
TAU_UP_BASE_S = 0.012
TAU_UP_PER_KG_S = 0.007
TAU_DOWN_OVER_UP = 1.3
ROTOR_DRAG_PER_KG = 0.1
FRONT_AREA_M2 = 0.02
TOP_AREA_M2 = 0.05
COLLISION_PER_ARM = 1.3


def synthesise(
    name: str,
    mass_kg: float,
    twr_max: float,
    alpha_xy_max_rad_s2: float,
    alpha_z_max_rad_s2: float,
    *,
    layout: str = "quad_x",
    category: str = "user",
    source: str = "",
) -> Platform:
    """Full physical parameters reproducing (mass, TWR_max, alpha_xy, alpha_z) exactly."""
    where = f"platform {name!r}"
    for key, v, lo, hi, unit in (
        ("mass_kg", mass_kg, 0.05, 50.0, "kg"),
        ("twr_max", twr_max, TWR_RANGE[0], TWR_RANGE[1], ""),
        ("alpha_xy_max_rad_s2", alpha_xy_max_rad_s2, 1.0, 20000.0, "rad/s^2"),
        ("alpha_z_max_rad_s2", alpha_z_max_rad_s2, 0.1, 5000.0, "rad/s^2"),
    ):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise PlatformError(f"{where}: {key}: {v!r} is not a finite number")
        if not lo <= v <= hi:
            u = f" {unit}" if unit else ""
            raise PlatformError(
                f"{where}: {key}: {v!r}{u} is outside the allowed range [{lo}, {hi}]{u}"
            )
    if layout not in LAYOUTS:
        raise PlatformError(
            f"{where}: layout: {layout!r} is not one of {', '.join(sorted(LAYOUTS))}"
        )
    lay = get_layout(layout)
    n = lay.n_rotors
    weight = mass_kg * G
    f_max = twr_max * weight / n
    f_min = IDLE_RATIO**2 * f_max

    def roll_torque(d: float) -> float:
        return max_axis_torques(allocation_matrix(lay, d, 1.0), f_min, f_max)[0]

    d = ARM_COEFF_M * mass_kg**ARM_MASS_EXPONENT
    gamma = roll_torque(d) / alpha_xy_max_rad_s2 / (mass_kg * d * d)
    if gamma > GAMMA_MAX:
        # gamma scales as 1/d: lengthen the arm until the frame is plausible.
        stretch = gamma / GAMMA_MAX
        if stretch > ARM_STRETCH_MAX:
            raise PlatformError(
                f"{where}: alpha_xy_max_rad_s2 {alpha_xy_max_rad_s2} is too low for a "
                f"{mass_kg} kg quadrotor with TWR {twr_max}: it needs an arm "
                f"{stretch:.2f}x the nominal length (at most {ARM_STRETCH_MAX}x)"
            )
        d *= stretch
    d = float(d)
    jxx = float(roll_torque(d) / alpha_xy_max_rad_s2)
    prop = PROP_PER_ARM * d
    c_t = CT_STATIC * RHO_AIR * prop**4 / (4.0 * math.pi**2)
    w_max = math.sqrt(f_max / c_t)
    w_min = IDLE_RATIO * w_max

    tau_z_per_kappa = float(max_axis_torques(allocation_matrix(lay, d, 1.0), f_min, f_max)[2])
    ratio = JZZ_OVER_JXX
    kappa = ratio * jxx * alpha_z_max_rad_s2 / tau_z_per_kappa
    k_lo, k_hi = (r * prop for r in KAPPA_PER_PROP_RANGE)
    if not k_lo <= kappa <= k_hi:
        kappa = min(max(kappa, k_lo), k_hi)
        ratio = kappa * tau_z_per_kappa / (jxx * alpha_z_max_rad_s2)
        r_lo, r_hi = JZZ_OVER_JXX_RANGE
        if not r_lo <= ratio <= r_hi:
            raise PlatformError(
                f"{where}: alpha_z_max_rad_s2 {alpha_z_max_rad_s2} against alpha_xy "
                f"{alpha_xy_max_rad_s2} needs Jzz/Jxx = {ratio:.2f} with a plausible "
                f"propeller torque ratio; a quadrotor frame has {r_lo}-{r_hi}"
            )
    jzz = ratio * jxx
    w_hover = math.sqrt(weight / (n * c_t))
    tau_up = TAU_UP_BASE_S + TAU_UP_PER_KG_S * mass_kg
    scale_area = mass_kg ** (2.0 / 3.0)
    front = 0.5 * RHO_AIR * FRONT_AREA_M2 * scale_area
    top = 0.5 * RHO_AIR * TOP_AREA_M2 * scale_area
    p = Platform(
        name=name,
        category=category,
        layout=layout,
        mass_kg=float(mass_kg),
        arm_length_m=d,
        inertia_kg_m2=(jxx, jxx, jzz),
        prop_diameter_m=prop,
        thrust_coefficient=c_t,
        torque_thrust_ratio_m=kappa,
        rotor_speed_min_rad_s=w_min,
        rotor_speed_max_rad_s=w_max,
        motor_tau_up_s=tau_up,
        motor_tau_down_s=TAU_DOWN_OVER_UP * tau_up,
        rotor_drag_coefficient=ROTOR_DRAG_PER_KG * mass_kg / (n * w_hover),
        body_drag_coefficient=(front, front, top),
        collision_radius_m=COLLISION_PER_ARM * d,
        source=source,
    )
    return validate(p)


def _features(p: Platform) -> tuple[float, float, float, float]:
    ind = p.indicators()
    return (p.mass_kg, ind.twr_max, ind.alpha_xy_max_rad_s2, ind.alpha_z_max_rad_s2)


def generate_virtual(
    count: int,
    seed: int,
    base: list[Platform],
    *,
    prefix: str = "GEN",
    max_attempts: int = 100,
) -> list[Platform]:
    """New virtual platforms inside the design space of ``base``.

    Each one is a random convex combination (Dirichlet weights over 2-3 base platforms)
    of mass and the three indicators in log space, then synthesised and validated like
    the catalog. The paper built its virtual set by scaling inside the documented design
    space; interpolation keeps every sample inside the hull of the base set.
    """
    if count < 1:
        raise PlatformError(f"count: {count} must be at least 1")
    if len(base) < 2:
        raise PlatformError("base: interpolation needs at least two platforms")
    rng = np.random.default_rng(seed)
    feats = np.log(np.array([_features(p) for p in base]))
    out: list[Platform] = []
    attempts = 0
    while len(out) < count:
        attempts += 1
        if attempts > max_attempts * count:
            raise PlatformError(
                f"could not generate {count} consistent platforms in {attempts - 1} draws"
            )
        k = int(rng.integers(2, min(3, len(base)) + 1))
        idx = rng.choice(len(base), size=k, replace=False)
        w = rng.dirichlet(np.ones(k))
        mass, twr, axy, az = np.exp(w @ feats[idx])
        mass = round(float(mass), 2)
        name = f"{mass:.2f}kg-{prefix}{seed}-{len(out) + 1}"
        try:
            p = synthesise(
                name,
                mass,
                float(twr),
                float(axy),
                float(az),
                category="virtual",
                source=(
                    f"generated by ft-sitl (seed {seed}) from "
                    + ", ".join(f"{base[i].name} x{wi:.3f}" for i, wi in zip(idx, w))
                ),
            )
        except PlatformError:
            continue
        out.append(p)
    return out
