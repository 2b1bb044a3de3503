"""Unit constants: the one copy. Inside the package everything is SI (rad, m, s); user-facing names carry
their unit (deg, deg/h, micro-g) and convert with these."""

from __future__ import annotations

import math

UG = 9.80665e-6  # m/s^2 per micro-g (standard gravity, as accelerometer data sheets use it)
MICRO_G = UG  # the simulator's name for the same constant
DEG_PER_H = math.pi / 180.0 / 3600.0  # rad/s per deg/h
PER_SQRT_H = 1.0 / 60.0  # 1/sqrt(s) per 1/sqrt(h): a random walk in x/sqrt(h) is x/60 per sqrt(s)
