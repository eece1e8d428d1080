"""ArUco + colour/depth perception of the shelf (docs/perception.md)."""
