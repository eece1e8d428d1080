"""The common bottom layer: scenario model and loader, YAML and errors, the feasibility contract, where the
package's files are, and the ROS helpers every node shares (node main, parameters, message conversions)."""
