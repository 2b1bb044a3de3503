"""The estimators' inputs: a log made ready for any estimator (prepare: validation, screening, mounting,
alignment), ping selection and screening, IMU gaps and DVL dropouts, depth, GNSS fixes, the time offset's first
guess."""
