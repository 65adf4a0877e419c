"""ft-sitl: the FLYINGTRUST quadrotor benchmark as a PX4-style software-in-the-loop simulator."""

__version__ = "0.1.0"

G = 9.80665
"""Standard gravity (m/s^2), used everywhere a weight or TWR is computed."""

# before numba and numpy load: the instruction-set level every numeric library computes at
from ft_sitl import numeric_env  # noqa: E402

try:
    numeric_env.warn_if_too_late(numeric_env.pin())
except numeric_env.NumericEnvError as _exc:  # a bad FT_SITL_ISA: one line, not a traceback
    raise SystemExit(f"ft-sitl: {_exc}") from None

from ft_sitl import jit_cache  # noqa: E402

JIT_CACHE_DIR = jit_cache.configure()
