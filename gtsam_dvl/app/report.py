"""The paper's findings checked on an estimator's sigma timeline, and the Markdown report of a run.

Each finding is a measurable statement about the filtering sigmas (ratio = sigma / prior sigma); the
report states for each estimator whether it held, with the numbers, so that a reader sees which of the
paper's claims our runs reproduce.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.result import Timeline
from gtsam_dvl.core.types import Segment


@dataclass
class Finding:
    text: str
    held: bool
    evidence: str


def _ratio_at(tl: Timeline, name: str, t: float, prior: np.ndarray | float) -> np.ndarray:
    i = min(int(np.searchsorted(tl.t, t)), len(tl.t) - 1)
    return np.atleast_1d(np.asarray(getattr(tl, name))[i]) / np.asarray(prior)


def _first_start(segments: list[Segment], kinds: tuple[str, ...]) -> float | None:
    return next((s.start_s for s in segments if s.kind in kinds), None)


def paper_findings(tl: Timeline, priors: dict[str, Any], segments: list[Segment]) -> list[Finding]:
    """The paper's findings (docs/conventions.md, "The paper's scenarios"), checked on one timeline. The times
    come from the run's segments: motion starts where the first segment that is not static starts, the roll
    finding needs a descent, the accelerometer-bias finding the first turns; a run that never changes depth is
    the paper's 2-D run."""
    motion_start_s = next((s.start_s for s in segments if s.kind != "static"), 0.0)
    descent_s = _first_start(segments, ("descent",))
    turns_s = _first_start(segments, ("square", "turn"))
    changes_depth = descent_s is not None or _first_start(segments, ("ascent",)) is not None
    return (
        _motion_findings(tl, priors, motion_start_s)
        + _manoeuvre_findings(tl, priors, descent_s, turns_s)
        + [_gyro_bias_finding(tl, priors)]
        + ([] if changes_depth else [_two_d_finding(tl, priors)])
    )


def _motion_findings(tl: Timeline, priors: dict[str, Any], motion_start_s: float) -> list[Finding]:
    """The findings on the start of motion: the scale, then the yaw and pitch misalignment, converge."""
    mis_p = priors["misalignment_deg"]
    out = []
    before, after = (
        _ratio_at(tl, "scale_sigma", motion_start_s - 1, priors["scale"])[0],
        _ratio_at(tl, "scale_sigma", motion_start_s + 60, priors["scale"])[0],
    )
    out.append(
        Finding(
            f"the scale converges as soon as motion starts at {motion_start_s:.0f} s",
            after < 0.1 * before,
            f"scale sigma/prior {before:.3f} at {motion_start_s - 1:.0f} s -> {after:.4f} at "
            f"{motion_start_s + 60:.0f} s",
        )
    )
    r = _ratio_at(tl, "misalignment_sigma_deg", motion_start_s + 60, mis_p)
    out.append(
        Finding(
            f"yaw and pitch misalignment converge from {motion_start_s:.0f} s",
            bool(np.all(r[1:] < 0.2)),
            f"pitch, yaw sigma/prior at {motion_start_s + 60:.0f} s: {r[1]:.3f}, {r[2]:.3f}",
        )
    )
    return out


def _manoeuvre_findings(
    tl: Timeline, priors: dict[str, Any], descent_s: float | None, turns_s: float | None
) -> list[Finding]:
    """The findings on the manoeuvres, when the run has them: the roll misalignment once the descent starts, the
    accelerometer bias after the turns start."""
    mis_p, acc_p = priors["misalignment_deg"], priors["accel_bias_ug"]
    out = []
    if descent_s is not None:
        pre = _ratio_at(tl, "misalignment_sigma_deg", descent_s - 1, mis_p)[0]
        post = _ratio_at(tl, "misalignment_sigma_deg", descent_s + 60, mis_p)[0]
        out.append(
            Finding(
                f"roll misalignment only once the descent starts at {descent_s:.0f} s",
                pre > 0.9 and post < 0.5,
                f"roll sigma/prior {pre:.3f} at {descent_s - 1:.0f} s -> "
                f"{post:.3f} at {descent_s + 60:.0f} s",
            )
        )
    if turns_s is not None:
        a_pre = _ratio_at(tl, "accel_bias_sigma_ug", turns_s - 1, acc_p)[:2]
        a_post = _ratio_at(tl, "accel_bias_sigma_ug", turns_s + 350, acc_p)[:2]
        out.append(
            Finding(
                "the accelerometer bias converges after the turns start",
                bool(np.all(a_pre > 0.8) and np.all(a_post < 0.3)),
                f"horizontal accel bias sigma/prior {np.round(a_pre, 3)} "
                f"before the turns -> {np.round(a_post, 3)} {350:.0f} s after they start",
            )
        )
    return out


def _gyro_bias_finding(tl: Timeline, priors: dict[str, Any]) -> Finding:
    """The finding on the gyro bias: it converges slowly, the vertical axis slowest."""
    g = np.asarray(tl.gyro_bias_sigma_deg_per_h)[-1] / np.asarray(priors["gyro_bias_deg_per_h"])
    return Finding(
        "the gyro bias converges slowly, the vertical axis slowest",
        bool(g[2] > max(g[0], g[1])),
        f"final gyro bias sigma/prior x, y, z: {np.round(g, 3)}",
    )


def _two_d_finding(tl: Timeline, priors: dict[str, Any]) -> Finding:
    """The 2-D run's finding: everything converges except the roll misalignment about the thrust axis."""
    mis_p = priors["misalignment_deg"]
    roll = np.asarray(tl.misalignment_sigma_deg)[:, 0] / np.asarray(mis_p)[0]
    others = np.concatenate(
        [
            [np.asarray(tl.scale_sigma)[-1] / priors["scale"]],
            np.asarray(tl.misalignment_sigma_deg)[-1, 1:] / np.asarray(mis_p)[1:],
        ]
    )
    return Finding(
        "2-D run: everything converges except the roll misalignment about the thrust axis",
        bool(roll.min() > 0.9 and np.all(others < 0.2)),
        f"roll sigma/prior never below {roll.min():.3f}; scale, pitch, yaw final "
        f"{np.round(others, 4)}",
    )


def _fmt(v: Any, digits: int = 4) -> str:
    if isinstance(v, list | tuple | np.ndarray):
        return ", ".join(_fmt(x, digits) for x in v)
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def calibration_table(summaries: list[dict[str, Any]]) -> list[str]:
    """Markdown rows: final calibration per estimator against the truth."""
    lines = [
        "| estimator | scale (err ppm / sigma ppm) | misalignment err r, p, y (deg) | sigma r, p, y (deg) | "
        "gyro bias err (deg/h) | accel bias err (micro-g) | final horiz. pos. err | attitude RMSE (deg) | "
        "wall (s) |",
        "|" + " --- |" * 9,
    ]
    for s in summaries:
        e = s.get("errors", {})
        scale = f"{e.get('scale_ppm', float('nan')):+.0f} / {s['scale']['sigma'] * 1e6:.0f}"
        pos = (
            f"{e['final_horizontal_position_m']:.2f} m ({e['final_horizontal_position_pct_distance']:.3f} %)"
            if "final_horizontal_position_m" in e
            else "-"
        )
        att = _fmt(e.get("attitude_rmse_deg", "-"), 3) if "attitude_rmse_deg" in e else "-"
        wall = s.get("timing_s", {}).get("total")
        wall_s = f"{wall:.1f}" if wall is not None else "-"
        lines.append(
            f"| {s['estimator']} | {scale} | {_fmt(e.get('misalignment_deg', '-'), 3)} | "
            f"{_fmt(s['misalignment_deg']['sigma'], 3)} | {_fmt(e.get('gyro_bias_deg_per_h', '-'), 2)} | "
            f"{_fmt(e.get('accel_bias_ug', '-'), 3)} | {pos} | {att} | {wall_s} |"
        )
    return lines


def write_run_report(
    path: Path,
    run: str,
    summaries: list[dict[str, Any]],
    findings: dict[str, list[Finding]],
    verdict: list[str],
    figures: list[Path],
) -> Path:
    """A Markdown report of one simulated run: table, findings per estimator, verdict, figures."""
    from gtsam_dvl.io.atomic import atomic_write_text

    lines = [
        f"# {run}: DVL self-calibration report",
        "",
        "Final estimates of every estimator against the simulated truth:",
        "",
        *calibration_table(summaries),
        "",
        "## The paper's findings, checked on each estimator's sigma timeline",
        "",
    ]
    for est, items in findings.items():
        lines.append(f"**{est}**")
        lines.append("")
        lines += [f"- {'yes' if f.held else 'NO'}: {f.text} ({f.evidence})" for f in items]
        lines.append("")
    lines += [
        "## Observability verdict (batch smoother)",
        "",
        "```",
        *verdict,
        "```",
        "",
        "## Figures",
        "",
    ]
    for fig in figures:
        rel = fig.relative_to(path.parent) if fig.is_relative_to(path.parent) else fig
        lines += [f"### {fig.stem.replace('_', ' ')}", "", f"![{fig.stem}]({rel.as_posix()})", ""]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def gnss_lines(gnss: dict[str, Any] | None) -> list[str]:
    """The printed lines of the GNSS check (metrics["gnss"] of `evaluate`, analysis/surfacing.py): how the fixes
    were used, the held-out fixes' errors and the surfacing error; no lines for a log without fixes."""
    if not gnss:
        return []
    c = gnss["counters"]
    lines = [
        f"GNSS: {c['gnss_used'] + c['gnss_held_out'] + c['gnss_rejected']} fixes in "
        f"{gnss['surface_intervals']} surface interval(s), use = {gnss['use']}: {c['gnss_used']} aided, "
        f"{c['gnss_held_out']} held out, {c['gnss_rejected']} rejected (status {c['gnss_rejected_status']}, "
        f"depth {c['gnss_rejected_depth']}, too far from a state {c['gnss_too_far']})"
    ]
    if not gnss["held_out_evaluated"]:
        lines.append(
            "GNSS: no held-out fixes, so no surfacing error (every good fix aided, or none came after the "
            'first dive); use = "start" holds out the fixes after the first surface interval'
        )
        return lines
    lines.append(
        f"GNSS: held-out fixes {gnss['held_out_evaluated']}, horizontal error rms "
        f"{gnss['held_out_horizontal_rms_m']:.2f} m"
    )
    s = gnss["surfacing_error"]
    if s is None:
        lines.append("surfacing error: none (the last surface interval has no held-out fix)")
        return lines
    lines.append(
        f"surfacing error (first held-out fix of the last surfacing, t = {s['t_s']:.1f} s): horizontal "
        f"{s['horizontal_error_m']:.2f} m = {s['horizontal_error_pct']:.3f} % of "
        f"{s['distance_m']:.0f} m travelled, vertical {s['vertical_error_m']:+.2f} m; sigma of the fix "
        f"{s['fix_sigma_h_m']:.2f} m horizontal, {s['fix_sigma_v_m']:.2f} m vertical; of the estimate "
        f"{s['estimate_sigma_h_m']:.2f} m, {s['estimate_sigma_v_m']:.2f} m"
    )
    m = gnss.get("surfacing_error_mean")
    if m is not None and gnss.get("surfacing_fixes", 0) > 1:
        lines.append(
            f"surfacing error, mean over the {gnss['surfacing_fixes']} held-out fixes of the last surfacing: "
            f"horizontal {m['horizontal_error_m']:.2f} m = {m['horizontal_error_pct']:.3f} % of "
            f"{m['distance_m']:.0f} m travelled, vertical {m['vertical_error_m']:+.2f} m; sigma of the "
            f"fixes' mean {m['fix_sigma_h_m']:.2f} m horizontal; of the estimate "
            f"{m['estimate_sigma_h_m']:.2f} m"
        )
    return lines
