"""Geometry-first object perception (docs/perception.md, "Objects"): the depth points above the boards, clustered
(`clusters`), each cluster fitted with a primitive (`primitives`), named by appearance and position (`identity`),
the robot's own body left out (`self_filter`). No rclpy here."""
