"""Planning a relocation (paper Sect. 4.1): RRT-Connect (OMPL), the STPIK check (Eq. 9-10), the
feasibility answer (Eq. 11) and the pick, carry and way home."""
