"""Navigators over the wire: MAVSDK offboard clients, trials judged on a served SITL.

- :mod:`ft_sitl.wire.convert`: a navigator's ENU setpoint as the MAVSDK offboard call PX4
  clients make (local NED, degrees);
- :mod:`ft_sitl.wire.navigate`: ``ft-sitl navigate``, any registered navigator as an
  out-of-process MAVSDK client (take-off, reach the start, stream setpoints);
- :mod:`ft_sitl.wire.trial`: one trial with the vehicle served over MAVLink (and the MQTT
  bus) and the navigator in another process, judged by the in-process protocol's code.
"""
