"""Navigators over the wire: MAVSDK offboard clients, trials judged on a served SITL.

- :mod:`ft_sitl.wire.convert`: a navigator's ENU setpoint as the MAVSDK offboard call PX4
  clients make (local NED, degrees);
- :mod:`ft_sitl.wire.navigate`: ``ft-sitl navigate``, any registered navigator as an
  out-of-process MAVSDK client (take-off, reach the start, stream setpoints);
- :mod:`ft_sitl.wire.sitl_bus`: one served vehicle's telemetry, events and depth frames on
  the MQTT bus.

The trial flown this way (the vehicle served over MAVLink, the navigator in another
process, judged by the protocol) is :mod:`ft_sitl.missions.trial_wire`, in the missions
layer above this one.
"""
