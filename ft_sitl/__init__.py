"""ft-sitl: the FLYINGTRUST quadrotor benchmark as a PX4-style software-in-the-loop simulator."""

__version__ = "0.1.0"

G = 9.80665
"""Standard gravity (m/s^2), used everywhere a weight or TWR is computed."""

# before numba and numpy load: BLAS threads and kernels that trial results depend on
from ft_sitl import numeric_env  # noqa: E402

numeric_env.pin()

from ft_sitl import jit_cache  # noqa: E402

JIT_CACHE_DIR = jit_cache.configure()
