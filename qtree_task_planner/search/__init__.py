"""Exact searches over removed sets (Eq. 8): the uniform-cost reference, the blocker A*, reachability."""
