"""The console lines of a run's summary (`gtsam-dvl smooth`, `gtsam-dvl info RESULT`), read from its typed model
(core/summary.py): the calibration and biases, the errors against a truth, the time offset, the noise levels,
the calibration prior, what was held and why, the water current, the motion and the health."""

from __future__ import annotations

import math

from gtsam_dvl.analysis.geometry import MotionSummary
from gtsam_dvl.analysis.observability import time_offset_words
from gtsam_dvl.core.summary import AnySummary, HealthSummary, Summary, TruthErrors


def summary_lines(s: AnySummary) -> list[str]:
    """SmoothOutcome.describe's lines but those of the files written."""
    if not isinstance(s, Summary):  # io-dvlc: calibration only
        return [
            f"{s.estimator}: scale {s.scale.value:.6f}, misalignment "
            f"{[round(v, 3) for v in s.misalignment_deg.value]} deg"
        ] + health_lines(s.health)
    mis = s.misalignment_deg
    lines = [
        f"{s.estimator}: {s.states} states over {s.duration_s:.0f} s, "
        f"{s.timing_s.get('total', math.nan):.2f} s wall",
        f"  scale        {s.scale.value:.6f} +- {s.scale.sigma:.6f}",
        "  misalignment roll/pitch/yaw "
        + ", ".join(f"{v:+.3f} +- {e:.3f}" for v, e in zip(mis.value, mis.sigma, strict=True))
        + " deg",
        "  gyro bias    " + ", ".join(f"{v:+.4f}" for v in s.gyro_bias_deg_per_h.value) + " deg/h",
        "  accel bias   " + ", ".join(f"{v:+.1f}" for v in s.accel_bias_ug.value) + " micro-g",
    ]
    lines += truth_error_lines(s.errors)
    if (off := s.dvl_time_offset_s) is not None:
        lines.insert(
            3,
            f"  DVL time offset {off.value * 1e3:+.1f} +- {off.sigma * 1e3:.1f} ms "
            f"({'determined' if off.determined else 'not determined'}): "
            f"{off.words or time_offset_words(off.value)}",
        )
    lines += [f"  noise: {line}" for line in s.noise_levels]
    from gtsam_dvl.app.calibration_files import prior_line

    lines += [line] if (line := prior_line(s.info)) else []
    lines += state_lines(s)
    if s.geometry is not None:
        lines.append(f"  {MotionSummary(**s.geometry.motion.model_dump()).line()}")
    return lines + health_lines(s.health)


def truth_error_lines(err: TruthErrors | None) -> list[str]:
    """The line of the errors against the truth (none without a truth)."""
    if err is None or err.final_horizontal_position_m is None:
        return []
    pct = err.final_horizontal_position_pct_distance
    of_distance = f"{pct:.3f} % of distance" if pct is not None else "no distance travelled"
    # a truth without calibration: left out, not NaN
    calibration = [f"scale {err.scale_ppm:+.0f} ppm"] if err.scale_ppm is not None else []
    if err.misalignment_deg:
        calibration.append(
            "misalignment " + ", ".join(f"{v:+.3f}" for v in err.misalignment_deg) + " deg"
        )
    position = f"final horizontal position {err.final_horizontal_position_m:.2f} m ({of_distance})"
    return ["  vs truth: " + ", ".join([*calibration, position])]


def state_lines(s: Summary) -> list[str]:
    """The lines on the calibration directions held (or released) and why, and on the water current."""
    lines = s.calibration_hold.lines() if s.calibration_hold is not None else []
    # water-track pings used, the current a state (estimators/models/current.py)
    if (wc := s.water_current) is not None:
        layers = "; ".join(
            f"{a.depth_m[0]:.0f}-{a.depth_m[1]:.0f} m {a.speed_m_s:.2f} +- {a.sigma_m_s:.2f} m/s"
            for a in wc.by_depth[:6]
        )
        per = (
            f" per {wc.layers.thickness_m:g} m layer ({wc.layers.boundaries} boundaries crossed)"
            if wc.layers is not None
            else ""
        )
        lines.append(
            f"  water current{per} ({wc.water_track_pings} water-track pings): {wc.verdict}"
            + (f"; {layers}" if layers else "")
        )
    return lines


def health_lines(health: HealthSummary | None, indent: str = "  ") -> list[str]:
    """The console lines of a summary's health: its status, then one line per warning and note (what the reader
    lost is among them)."""
    if health is None:
        return []
    return (
        [f"{indent}health: {health.status}"]
        + [f"{indent}  warning: {w}" for w in health.warnings]
        + [f"{indent}  note: {n}" for n in health.notes]
    )
