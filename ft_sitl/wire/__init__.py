"""Navigators over the wire: the client side, MAVSDK offboard navigators.

- :mod:`ft_sitl.wire.convert`: a navigator's ENU setpoint as the MAVSDK offboard call PX4
  clients make (local NED, degrees);
- :mod:`ft_sitl.wire.navigate`: ``ft-sitl navigate``, any registered navigator as an
  out-of-process MAVSDK client (take-off, reach the start, stream setpoints).

The simulator's side (the trial served over MAVLink and judged by the protocol, the
vehicle on the MQTT bus) is :mod:`ft_sitl.transport`, above the missions layer.
"""
