"""The batch smoother: its front (smoother), every solve (solve), several dives or pieces of one log as one
calibration (multi_dive, pieces), the filtering timeline over its linearisation (timeline)."""
