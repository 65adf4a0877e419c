"""The planning navigators: the straight-flight baseline, EGO-Planner, Fast-Planner and PGO,
each a small module over the replanning skeleton (:mod:`.skeleton`), with their front ends
(voxel A*, kinodynamic A*, the topological roadmap)."""
