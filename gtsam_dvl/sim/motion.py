"""Analytic vehicle motion in the local-level ENU frame l (at the vehicle's current position).

Each elementary piece has closed-form speed, vertical speed and Euler angles with analytic time
derivatives (sim/blends.py):

    s(t)   = s0 + ds step5(tau) + bump bump6(tau)        horizontal speed, m/s
    w(t)   = w_peak bump6(tau)                           vertical speed (up), m/s
    yaw    = yaw0 + dyaw step7(tau)                      ENU yaw, rad (counter-clockwise from east)
    roll   = roll0 + bank bump6(tau)                     the bank follows the turn rate's shape
    pitch  = pitch0

with tau = (t - t_start) / T clamped to [0, 1]. The vehicle moves along its heading (course = yaw, no
sideslip), so v^l = [s cos(yaw), s sin(yaw), w] and, at zero pitch, the horizontal velocity stays on the
body x axis: the thrust-axis misalignment of the DVL is then unobservable unless w changes (paper Remark 3).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.sim.blends import bump6, step5, step7

if TYPE_CHECKING:
    from gtsam_dvl.sim.scenario import Scenario

_FIELDS = ("t_start", "duration", "s0", "ds", "bump", "w_peak", "yaw0", "dyaw", "roll0", "bank", "pitch0")


@dataclass
class MotionState:
    """Motion quantities at an array of times (all (K,) arrays, SI units, radians)."""

    s: np.ndarray
    s_dot: np.ndarray
    w: np.ndarray
    w_dot: np.ndarray
    yaw: np.ndarray
    yaw_dot: np.ndarray
    pitch: np.ndarray
    pitch_dot: np.ndarray
    roll: np.ndarray
    roll_dot: np.ndarray

    def l_v(self) -> np.ndarray:
        """Velocity relative to the Earth in the local level, (K, 3) m/s."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.stack([self.s * c, self.s * s, self.w], axis=-1)

    def l_v_dot(self) -> np.ndarray:
        """Time derivative of the local-level components of l_v, (K, 3) m/s^2."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.stack(
            [self.s_dot * c - self.s * self.yaw_dot * s, self.s_dot * s + self.s * self.yaw_dot * c, self.w_dot],
            axis=-1,
        )

    def l_R_b(self) -> np.ndarray:
        """Attitude Rz(yaw) Ry(pitch) Rx(roll), (K, 3, 3)."""
        cy, sy = np.cos(self.yaw), np.sin(self.yaw)
        cp, sp = np.cos(self.pitch), np.sin(self.pitch)
        cr, sr = np.cos(self.roll), np.sin(self.roll)
        R = np.empty((*self.yaw.shape, 3, 3))
        R[..., 0, 0] = cy * cp
        R[..., 0, 1] = cy * sp * sr - sy * cr
        R[..., 0, 2] = cy * sp * cr + sy * sr
        R[..., 1, 0] = sy * cp
        R[..., 1, 1] = sy * sp * sr + cy * cr
        R[..., 1, 2] = sy * sp * cr - cy * sr
        R[..., 2, 0] = -sp
        R[..., 2, 1] = cp * sr
        R[..., 2, 2] = cp * cr
        return R

    def b_omega_lb(self) -> np.ndarray:
        """Body rate relative to the local level in base_link, (K, 3) rad/s, from the ZYX Euler rates."""
        cp, sp = np.cos(self.pitch), np.sin(self.pitch)
        cr, sr = np.cos(self.roll), np.sin(self.roll)
        return np.stack(
            [
                self.roll_dot - self.yaw_dot * sp,
                self.pitch_dot * cr + self.yaw_dot * cp * sr,
                -self.pitch_dot * sr + self.yaw_dot * cp * cr,
            ],
            axis=-1,
        )


class MotionProfile:
    """The scenario's motion as elementary pieces, evaluated vectorised at any times."""

    def __init__(self, pieces: list[dict[str, float]]) -> None:
        self.p = {k: np.array([pc[k] for pc in pieces], dtype=float) for k in _FIELDS}

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> MotionProfile:
        """Expand the scenario's segments (a square becomes legs and turns) into elementary pieces."""
        ini = scenario.initial
        state = {"s0": ini.speed_m_s, "yaw0": np.radians(ini.yaw_deg), "roll0": np.radians(ini.roll_deg),
                 "pitch0": np.radians(ini.pitch_deg)}
        pieces: list[dict[str, float]] = []

        def add(t0: float, T: float, ds: float = 0.0, bump: float = 0.0, w_peak: float = 0.0,
                dyaw: float = 0.0, bank: float = 0.0) -> None:
            pieces.append({"t_start": t0, "duration": T, "ds": ds, "bump": bump, "w_peak": w_peak,
                           "dyaw": dyaw, "bank": bank, **state})
            state["s0"] += ds
            state["yaw0"] += dyaw

        for seg in scenario.segments:
            T = seg.duration_s
            if seg.kind in ("static", "straight"):
                add(seg.start_s, T)
            elif seg.kind == "level":
                end = state["s0"] if seg.speed_end_m_s is None else seg.speed_end_m_s
                add(seg.start_s, T, ds=end - state["s0"], bump=seg.speed_bump_m_s)
            elif seg.kind in ("descent", "ascent"):
                sign = -1.0 if seg.kind == "descent" else 1.0
                add(seg.start_s, T, w_peak=sign * seg.peak_vertical_speed_m_s)
            elif seg.kind == "turn":
                dyaw = np.radians(seg.heading_change_deg)
                # bank into the turn: a left turn (yaw increasing) lowers the left side, roll < 0 in FLU
                add(seg.start_s, T, dyaw=dyaw, bank=-np.sign(dyaw) * np.radians(seg.bank_deg))
            elif seg.kind == "square":
                sign = 1.0 if seg.direction == "left" else -1.0
                t = seg.start_s
                for _ in range(seg.sides):
                    for part in (("turn", "leg") if seg.turn_first else ("leg", "turn")):
                        if part == "leg":
                            add(t, seg.leg_duration_s)
                            t += seg.leg_duration_s
                        else:
                            add(t, seg.turn_duration_s, dyaw=sign * 2.0 * np.pi / seg.sides,
                                bank=-sign * np.radians(seg.bank_deg))
                            t += seg.turn_duration_s
            else:  # the loader rejects unknown kinds; this guards programmatic scenarios
                raise ValueError(f"unknown segment kind {seg.kind!r}")
        return cls(pieces)

    def evaluate(self, t: np.ndarray) -> MotionState:
        """Motion at times t (any shape); before 0 and after the end the end states continue."""
        t = np.asarray(t, dtype=float)
        flat = t.ravel()
        p = self.p
        n_pieces = len(p["t_start"])
        if flat.size > 1 and np.all(flat[1:] >= flat[:-1]):
            # sorted times (the usual case): each piece is a slice, no gathers of its parameters
            bounds = np.concatenate([[0], np.searchsorted(flat, p["t_start"][1:], side="right"), [flat.size]])
            out = {f: np.empty(flat.size) for f in _STATE}
            for j in range(n_pieces):
                sl = slice(bounds[j], bounds[j + 1])
                if sl.start < sl.stop:
                    _piece(out, sl, flat[sl], {k: v[j] for k, v in p.items()})
        else:
            i = np.clip(np.searchsorted(p["t_start"], flat, side="right") - 1, 0, n_pieces - 1)
            out = {f: np.empty(flat.size) for f in _STATE}
            _piece(out, slice(None), flat, {k: v[i] for k, v in p.items()})
        return MotionState(**{f: out[f].reshape(t.shape) for f in _STATE})


_STATE = ("s", "s_dot", "w", "w_dot", "yaw", "yaw_dot", "pitch", "pitch_dot", "roll", "roll_dot")


def _piece(out: dict[str, np.ndarray], sl: slice, t: np.ndarray, q: dict[str, Any]) -> None:
    """Fill out[...][sl] at times t from piece parameters q (scalars, or arrays matching t)."""
    T = q["duration"]
    tau = np.clip((t - q["t_start"]) / T, 0.0, 1.0)
    st, dst = step5(tau)
    bu, dbu = bump6(tau)
    s7, ds7 = step7(tau)
    out["s"][sl] = q["s0"] + q["ds"] * st + q["bump"] * bu
    out["s_dot"][sl] = (q["ds"] * dst + q["bump"] * dbu) / T
    out["w"][sl] = q["w_peak"] * bu
    out["w_dot"][sl] = q["w_peak"] * dbu / T
    out["yaw"][sl] = q["yaw0"] + q["dyaw"] * s7
    out["yaw_dot"][sl] = q["dyaw"] * ds7 / T
    out["pitch"][sl] = q["pitch0"]
    out["pitch_dot"][sl] = 0.0
    out["roll"][sl] = q["roll0"] + q["bank"] * bu
    out["roll_dot"][sl] = q["bank"] * dbu / T
