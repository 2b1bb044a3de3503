"""The small scenario of the campaign and fleet tests (tests/app/test_campaign.py, tests/app/test_fleet.py)."""

# 240 s: a static minute, a speed-up and surge, a descent and a banked turn (every calibration state informed)
SCENARIO = """
name = "mc-tiny"
estimator_config = "paper"
[origin]
lat_deg = 30.0
lon_deg = 114.0
height_m = -100.0
[rates]
imu_hz = 100.0
dvl_hz = 1.0
[initial]
roll_deg = 3.0
yaw_deg = 10.0
[dvl]
scale = 0.9998
misalignment_deg = [-0.1, 0.2, -0.5]
noise_m_s = 0.02
[[segments]]
kind = "static"
duration_s = 60.0
[[segments]]
kind = "level"
duration_s = 15.0
speed_end_m_s = 2.0
[[segments]]
kind = "level"
duration_s = 45.0
speed_bump_m_s = 0.5
[[segments]]
kind = "descent"
duration_s = 60.0
peak_vertical_speed_m_s = 0.8
[[segments]]
kind = "turn"
duration_s = 60.0
heading_change_deg = 90.0
bank_deg = 15.0
"""
