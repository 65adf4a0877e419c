"""The planners' view of the world: the local occupancy map fused from the depth camera
(:mod:`.mapping`) and the snapshot of its ESDF a plan reads (:mod:`.esdf`)."""
