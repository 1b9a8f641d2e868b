"""The vehicle's true motion: attitude conventions and trajectories."""
