"""Unit conversions from the scenario files' units to SI."""

from __future__ import annotations

import math

MICRO_G = 9.80665e-6  # m/s^2 per micro-g (standard gravity, as accelerometer data sheets use it)
DEG_PER_H = math.pi / 180.0 / 3600.0  # rad/s per deg/h
PER_SQRT_H = 1.0 / 60.0  # 1/sqrt(s) per 1/sqrt(h): a random walk in x/sqrt(h) is x/60 per sqrt(s)
