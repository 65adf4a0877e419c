"""Trajectory optimisers: the L-BFGS (:mod:`.lbfgs`), the penalties the planners share
(:mod:`.penalties`) and each planner's cost and solve (:mod:`.ego`, :mod:`.fast`,
:mod:`.pgo`)."""
