"""Executing a retrieval: the optimum, training and relocations in order (retrieval), checked after
each relocation and re-planned (closed_loop, replan), over planner replicas, with checkpoints kept and planner
outages survived."""
