"""Simulator of IMU, DVL and truth from a scenario: physics independent of the estimator (no GTSAM)."""

from gtsam_dvl.sim.simulate import simulate

__all__ = ["simulate"]
