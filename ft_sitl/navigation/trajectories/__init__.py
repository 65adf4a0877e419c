"""Trajectories: the protocol every planned curve follows (:mod:`.base`), the B-spline
(:mod:`.bspline`; EGO's fit in :mod:`.bspline_fit`, the knots of Fast-Planner's re-timings
in :mod:`.bspline_retime`) and the piecewise (min-snap) polynomial (:mod:`.minsnap`)."""
