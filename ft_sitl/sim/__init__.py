"""The simulation layer: vehicles stepped in lockstep (controller + plant), their flight
controllers' commanders (:class:`~ft_sitl.sim.fleet.Fleet`) and the collision guard inside
the compiled loop. It sits above :mod:`ft_sitl.physics`, :mod:`ft_sitl.autopilot` and
:mod:`ft_sitl.scenarios`; the MAVLink layer, the bridges and the mission runner build on it.
"""
