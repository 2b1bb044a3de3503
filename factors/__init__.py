"""Custom GTSAM factors for the DVL (installed as gtsam_dvl.factors)."""
