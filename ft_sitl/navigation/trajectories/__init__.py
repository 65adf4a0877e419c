"""Trajectories: the protocol every planned curve follows (:mod:`.base`), the B-spline
(:mod:`.bspline`) and the piecewise (min-snap) polynomial (:mod:`.minsnap`)."""
