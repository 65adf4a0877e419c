import math

import numpy as np
import pytest

from ft_sitl import frames
from ft_sitl.physics.quaternion import qfrom_euler, qrotate


def test_vector_conversions():
    assert frames.enu_to_ned([1.0, 2.0, 3.0]).tolist() == [2.0, 1.0, -3.0]
    assert frames.flu_to_frd([1.0, 2.0, 3.0]).tolist() == [1.0, -2.0, -3.0]
    v = np.random.default_rng(0).normal(size=(5, 3))
    assert np.allclose(frames.ned_to_enu(frames.enu_to_ned(v)), v)


@pytest.mark.parametrize("yaw_enu", [0.0, 0.5, math.pi / 2, -2.0, 3.0])
def test_yaw_conversions(yaw_enu):
    ned = frames.yaw_enu_to_ned(yaw_enu)
    # heading east in ENU (0) is 90 deg in NED; north (pi/2) is 0
    assert math.isclose(math.cos(ned), math.sin(yaw_enu), abs_tol=1e-12)
    assert math.isclose(frames.wrap_pi(frames.yaw_ned_to_enu(ned) - yaw_enu), 0.0, abs_tol=1e-12)


def test_attitude_quaternion_conversion_rotates_vectors_consistently():
    q_enu_flu = qfrom_euler(0.3, -0.2, 1.1)
    q_ned_frd = frames.q_enu_flu_to_ned_frd(q_enu_flu)
    v_flu = np.array([0.4, -1.0, 2.0])
    v_enu = qrotate(q_enu_flu, v_flu)
    v_ned = qrotate(q_ned_frd, frames.flu_to_frd(v_flu))
    assert np.allclose(frames.enu_to_ned(v_enu), v_ned)
    back = frames.q_ned_frd_to_enu_flu(q_ned_frd)
    assert np.allclose(back, q_enu_flu)


def test_geodesy_round_trip_and_scale():
    ref = frames.GeoReference(*frames.PX4_SITL_HOME)
    assert np.allclose(ref.to_local(*frames.PX4_SITL_HOME), 0.0)
    for p in ([100.0, 0.0, 5.0], [0.0, -250.0, 0.0], [1234.5, 987.6, -3.0]):
        lat, lon, alt = ref.to_global(p)
        assert np.allclose(ref.to_local(lat, lon, alt), p, atol=1e-6)
    # 1e-3 deg of latitude is ~111.2 m north
    north = ref.to_local(frames.PX4_SITL_HOME[0] + 1e-3, frames.PX4_SITL_HOME[1], 488.0)
    assert north[1] == pytest.approx(111.19, abs=0.05) and abs(north[0]) < 1e-6
    with pytest.raises(ValueError, match="latitude"):
        frames.GeoReference(95.0, 0.0, 0.0)
