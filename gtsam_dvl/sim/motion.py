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

An arc (a steady turn) adds yaw_rate * clip(t - t_start, lo, hi) to the yaw, with [lo, hi] = [0, T]: its turn
rate starts and stops at once (at a segment boundary, which is an IMU stamp when the durations are multiples of
the sample interval, so each sample's quadrature sees one side only). A first arc holds its rate before t = 0
(lo = -inf) and a last one after its end (hi = +inf): a log that starts while the vehicle already turns.

Oscillation (optional, the scenario's [oscillation] table): sums of a sin(2 pi t / period) added to roll, pitch and
yaw and a heave a sin(2 pi t / period) in metres (its derivative added to w), over the whole run. The truth, the IMU
and the DVL all come from these same states, so they agree; the sinusoids keep the IMU's outputs moving across
its quantisation steps, as a real vehicle's small motions do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.sim.blends import bump6, step5, step7

if TYPE_CHECKING:
    from gtsam_dvl.sim.scenario import Scenario

_FIELDS = (
    "t_start",
    "duration",
    "s0",
    "ds",
    "bump",
    "w_peak",
    "yaw0",
    "dyaw",
    "roll0",
    "bank",
    "pitch0",
    "yaw_rate",
    "arc_lo",
    "arc_hi",
)


@dataclass(frozen=True)
class Oscillation:
    """Sinusoids added to the motion (module doc): terms (channel, amplitude, angular frequency rad/s), channel
    "roll", "pitch" or "yaw" (amplitude in rad) or "heave" (m). Each term is amplitude * sin(omega t), zero at
    t = 0."""

    terms: tuple[tuple[str, float, float], ...]


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
            [
                self.s_dot * c - self.s * self.yaw_dot * s,
                self.s_dot * s + self.s * self.yaw_dot * c,
                self.w_dot,
            ],
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

    def __init__(
        self, pieces: list[dict[str, float]], oscillation: Oscillation | None = None
    ) -> None:
        self.p = {k: np.array([pc[k] for pc in pieces], dtype=float) for k in _FIELDS}
        self.oscillation = oscillation

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> MotionProfile:
        """Expand the scenario's segments (a square becomes legs and turns) into elementary pieces."""
        ini = scenario.initial
        state = {
            "s0": ini.speed_m_s,
            "yaw0": np.radians(ini.yaw_deg),
            "roll0": np.radians(ini.roll_deg),
            "pitch0": np.radians(ini.pitch_deg),
        }
        pieces: list[dict[str, float]] = []

        def add(
            t0: float,
            T: float,
            ds: float = 0.0,
            bump: float = 0.0,
            w_peak: float = 0.0,
            dyaw: float = 0.0,
            bank: float = 0.0,
            yaw_rate: float = 0.0,
        ) -> None:
            pieces.append(
                {
                    "t_start": t0,
                    "duration": T,
                    "ds": ds,
                    "bump": bump,
                    "w_peak": w_peak,
                    "dyaw": dyaw,
                    "bank": bank,
                    "yaw_rate": yaw_rate,
                    "arc_lo": 0.0,
                    "arc_hi": T,
                    **state,
                }
            )
            state["s0"] += ds
            state["yaw0"] += dyaw + yaw_rate * T

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
                    for part in ("turn", "leg") if seg.turn_first else ("leg", "turn"):
                        if part == "leg":
                            add(t, seg.leg_duration_s)
                            t += seg.leg_duration_s
                        else:
                            add(
                                t,
                                seg.turn_duration_s,
                                dyaw=sign * 2.0 * np.pi / seg.sides,
                                bank=-sign * np.radians(seg.bank_deg),
                            )
                            t += seg.turn_duration_s
            elif seg.kind == "arc":
                add(seg.start_s, T, yaw_rate=np.radians(seg.turn_rate_deg_s))
            else:  # the loader rejects unknown kinds; this guards programmatic scenarios
                raise ValueError(f"unknown segment kind {seg.kind!r}")
        if pieces and pieces[0]["yaw_rate"] != 0.0:
            pieces[0]["arc_lo"] = -np.inf  # already turning before t = 0
        if pieces and pieces[-1]["yaw_rate"] != 0.0:
            pieces[-1]["arc_hi"] = np.inf  # still turning after the end
        return cls(pieces, _oscillation(scenario))

    def evaluate(self, t: np.ndarray) -> MotionState:
        """Motion at times t (any shape); before 0 and after the end the end states continue."""
        t = np.asarray(t, dtype=float)
        flat = t.ravel()
        p = self.p
        n_pieces = len(p["t_start"])
        if flat.size > 1 and np.all(flat[1:] >= flat[:-1]):
            # sorted times (the usual case): each piece is a slice, no gathers of its parameters
            bounds = np.concatenate(
                [[0], np.searchsorted(flat, p["t_start"][1:], side="right"), [flat.size]]
            )
            out = {f: np.empty(flat.size) for f in _STATE}
            for j in range(n_pieces):
                sl = slice(bounds[j], bounds[j + 1])
                if sl.start < sl.stop:
                    _piece(out, sl, flat[sl], {k: v[j] for k, v in p.items()})
        else:
            i = np.clip(np.searchsorted(p["t_start"], flat, side="right") - 1, 0, n_pieces - 1)
            out = {f: np.empty(flat.size) for f in _STATE}
            _piece(out, slice(None), flat, {k: v[i] for k, v in p.items()})
        if self.oscillation is not None:
            _oscillate(out, flat, self.oscillation)
        return MotionState(**{f: out[f].reshape(t.shape) for f in _STATE})


def _oscillation(scenario: Scenario) -> Oscillation | None:
    """The scenario's [oscillation] table as terms in radians, or None."""
    spec = scenario.oscillation
    if spec is None:
        return None
    terms = []
    for channel, amplitudes, periods in spec.channels():
        scale = 1.0 if channel == "heave" else np.pi / 180.0
        terms += [
            (channel, a * scale, 2.0 * np.pi / p)
            for a, p in zip(amplitudes, periods, strict=True)
            if a != 0.0
        ]
    return Oscillation(tuple(terms))


def _oscillate(out: dict[str, np.ndarray], t: np.ndarray, osc: Oscillation) -> None:
    """Add the oscillation's terms (and their time derivatives) to the states out at times t."""
    for name, a, w in osc.terms:
        s, c = np.sin(w * t), np.cos(w * t)
        if name == "heave":  # height a sin(w t): vertical speed a w cos(w t)
            out["w"] += a * w * c
            out["w_dot"] -= a * w * w * s
        else:
            out[name] += a * s
            out[f"{name}_dot"] += a * w * c


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
    rate = q["yaw_rate"]
    if np.any(rate != 0.0):  # arcs only: other pieces keep their bits
        d = t - q["t_start"]
        lo, hi = q["arc_lo"], q["arc_hi"]
        out["yaw"][sl] += rate * np.clip(d, lo, hi)
        out["yaw_dot"][sl] += np.where((d >= lo) & (d <= hi), rate, 0.0)
    out["pitch"][sl] = q["pitch0"]
    out["pitch_dot"][sl] = 0.0
    out["roll"][sl] = q["roll0"] + q["bank"] * bu
    out["roll_dot"][sl] = q["bank"] * dbu / T
