"""The simulated world: scenarios, trajectories, biased encoders, the delayed depth camera."""
