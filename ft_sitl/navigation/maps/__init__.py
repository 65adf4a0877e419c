"""The planners' view of the world: the local occupancy map fused from the depth camera
(:mod:`.mapping`), its signed ESDF (:mod:`.map_esdf`) and the snapshot of that ESDF a plan
reads (:mod:`.esdf`)."""
