"""`gtsam-dvl characterise LOG -o DIR`: what a log says about its sensors, and the [imu] / [dvl] settings it
recommends.

- Every sensor's stream (IMU, DVL, depth, GNSS when present): the rate (1 / the median stamp spacing), the stamp
  jitter (std and largest deviation of the spacings from that median, gaps left out) and the gaps (a spacing
  longer than GAP_PERIODS nominal periods).
- IMU: the quantisation step of every axis, found from the samples (core/sensor_noise.py quantisation_step), and
  the white-noise density its rounding error adds, q / sqrt(12 f), against the configured density; the Allan
  deviation of every axis on the longest static stretch of at least MIN_STATIC_S (static_stretches), else on the
  whole log with a warning (the motion then dominates all but the shortest averaging times), with its white
  density and bias instability (allan_fit); allan.png draws the curves with the configured densities
  (sigma(tau) = N / sqrt(tau)) and the quantisation floors.
- DVL: the batch smoother run with the noise fit on ([noise] from_data and fit_dvl, whatever the configuration
  says: estimators/models/noise_levels.py), its fitted ping sigma, chi^2/dof (the whole graph's and the DVL rows'), the
  residuals' autocorrelation and a white plus first-order Gauss-Markov fit of them (gauss_markov_fit).
- The recommendation: each IMU white noise raised to its quantisation floor (root sum of squares, as the
  estimators do), or to the static Allan white density when that is larger by STATIC_RAISE_FACTOR (the axes whose
  static samples scatter over fewer than STATIC_MIN_STEPS steps left out, as the estimators do); the DVL sigma the
  fit found.
  recommended.toml loads with `gtsam-dvl smooth LOG -c DIR/recommended.toml`; as the floor is already in [imu],
  it turns [noise] imu_quantisation off (else the estimators would add the floor a second time).

Writes DIR/characterise.json (every number), DIR/allan.png and DIR/recommended.toml as one set (io/atomic.py
OutputSet: all of them or none); refuses a DIR that exists and is not empty unless force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.sensor_noise import (
    AllanCurve,
    allan_deviation,
    allan_fit,
    autocovariance,
    gauss_markov_fit,
    imu_quantisation,
    quantisation_density,
)
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.models.noise_levels import STATIC_MIN_STEPS, STATIC_RAISE_FACTOR

if TYPE_CHECKING:
    from gtsam_dvl.io.read_options import ReadOptions

GAP_PERIODS = 2.0  # a stamp spacing longer than this many nominal periods is a gap
# static stretches: 1 s blocks of IMU samples whose mean turn rate is below STATIC_RATE_DEG_S (Earth rate is
# 0.004 deg/s), whose mean specific force differs by less than STATIC_DF_M_S2 from both neighbouring blocks',
# and, where the DVL has valid pings within STATIC_PING_WINDOW_S, whose DVL speed (median of 5 pings) is below
# STATIC_SPEED_M_S (a cruise at constant velocity looks static to the IMU, not to the DVL)
STATIC_BLOCK_S = 1.0
STATIC_RATE_DEG_S = 0.05
STATIC_DF_M_S2 = 0.02
STATIC_SPEED_M_S = 0.1
STATIC_PING_WINDOW_S = 5.0
MIN_STATIC_S = 60.0  # shorter static stretches give no Allan deviation beyond a few seconds
# DVL residual autocorrelation reported at lags 0..this many pings, or AUTOCORR_SPAN_S if that is more (bottom-track
# errors are correlated over seconds to minutes)
AUTOCORR_LAGS = 30
AUTOCORR_SPAN_S = 60.0
# an IMU axis whose samples repeat the previous one more often than this does not sweep its quantisation steps:
# its rounding error is a slowly changing bias, not white noise (white noise of sigma s on a step q repeats with a
# probability of about q / (2 sqrt(pi) s): 0.3 at s = q)
STUCK_FRACTION = 0.5
AXES = ("x", "y", "z")
OUTPUT_FILES = ("characterise.json", "allan.png", "recommended.toml")


def stream_timing(t: np.ndarray) -> dict[str, Any]:
    """Rate, stamp jitter and gaps of a stream stamped t (s): rate_hz = 1 / the median positive spacing; jitter
    the std and the largest absolute deviation of the spacings from it, over the spacings that are not gaps
    (longer than GAP_PERIODS periods); gaps their number, the time they lose beyond one period, the longest;
    non_increasing the spacings <= 0 (repeated or backwards stamps)."""
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    out: dict[str, Any] = {"messages": int(len(t))}
    dt = np.diff(t)
    positive = dt[dt > 0]
    if not len(positive):
        return out
    period = float(np.median(positive))
    gap = dt > GAP_PERIODS * period
    dev = dt[~gap & (dt > 0)] - period
    out.update(
        duration_s=float(t[-1] - t[0]),
        rate_hz=1.0 / period,
        period_s=period,
        jitter_std_s=float(np.std(dev)) if len(dev) else 0.0,
        jitter_max_s=float(np.max(np.abs(dev))) if len(dev) else 0.0,
        gaps=int(gap.sum()),
        gap_lost_s=float(np.sum(dt[gap] - period)),
        longest_gap_s=float(dt[gap].max()) if gap.any() else 0.0,
        non_increasing=int((dt <= 0).sum()),
    )
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True in mask."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(
        zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True)
    )


def static_stretches(log: LogData, rate_hz: float) -> list[tuple[float, float]]:
    """The stretches (start, end in s of the IMU stamps) where the vehicle is at rest, at least MIN_STATIC_S
    long, longest first (module doc: IMU block means and the DVL speed)."""
    imu = log.imu
    m = max(1, int(round(STATIC_BLOCK_S * rate_hz)))
    nb = len(imu.t) // m
    if nb < 2:
        return []
    w = np.asarray(imu.b_omega[: nb * m], dtype=float).reshape(nb, m, 3).mean(axis=1)
    f = np.asarray(imu.b_f[: nb * m], dtype=float).reshape(nb, m, 3).mean(axis=1)
    df = np.linalg.norm(np.diff(f, axis=0), axis=1)
    # a block is still when its mean differs little from both neighbours' (the first and last: from their one)
    df_block = np.maximum(np.concatenate([[0.0], df]), np.concatenate([df, [0.0]]))
    still = (np.linalg.norm(w, axis=1) < math.radians(STATIC_RATE_DEG_S)) & (
        df_block < STATIC_DF_M_S2
    )
    t_mid = np.asarray(imu.t[: nb * m], dtype=float).reshape(nb, m).mean(axis=1)
    dvl = log.dvl
    ok = (
        np.asarray(dvl.valid, dtype=bool) & np.isfinite(dvl.d_v).all(axis=1)
        if len(dvl)
        else np.zeros(0, bool)
    )
    if ok.sum() >= 5:
        t_p = np.asarray(dvl.t, dtype=float)[ok]
        speed = np.linalg.norm(dvl.d_v[ok], axis=1)
        speed = np.median(
            np.lib.stride_tricks.sliding_window_view(np.pad(speed, 2, mode="edge"), 5), axis=1
        )
        j = np.clip(np.searchsorted(t_p, t_mid), 1, len(t_p) - 1)
        j = np.where(np.abs(t_p[j - 1] - t_mid) < np.abs(t_p[j] - t_mid), j - 1, j)
        seen = np.abs(t_p[j] - t_mid) <= STATIC_PING_WINDOW_S
        still &= ~(seen & (speed[j] >= STATIC_SPEED_M_S))
    t = np.asarray(imu.t, dtype=float)
    # one block off each end: a motion that starts smoothly (a C2 blend) shows in the block means only once it
    # has grown for a while
    out = [(float(t[(a + 1) * m]), float(t[(b - 1) * m - 1])) for a, b in _runs(still) if b - a > 2]
    return sorted((s for s in out if s[1] - s[0] >= MIN_STATIC_S), key=lambda s: s[0] - s[1])


def allan_curves(
    log: LogData, rate_hz: float, span: tuple[float, float] | None
) -> list[AllanCurve]:
    """Allan deviation and fit of the three gyro axes (deg/h) and accelerometer axes (micro-g) of the IMU samples
    within span (s; None: the whole log)."""
    t = np.asarray(log.imu.t, dtype=float)
    sel = np.ones(len(t), bool) if span is None else (t >= span[0]) & (t <= span[1])
    curves = []
    for sensor, data, unit in (("gyro", log.imu.b_omega, DEG_PER_H), ("accel", log.imu.b_f, UG)):
        x = np.asarray(data, dtype=float)[sel] / unit
        for k, axis in enumerate(AXES):
            taus, adev = allan_deviation(x[:, k], rate_hz)
            pos = adev > 0
            fit = allan_fit(taus[pos], adev[pos]) if pos.sum() >= 2 else None
            curves.append(
                AllanCurve(
                    sensor,
                    axis,
                    taus,
                    adev,
                    fit.white_density if fit else None,
                    fit.bias_instability if fit else None,
                    bool(fit and fit.bias_bound),
                )
            )
    return curves


def imu_section(
    log: LogData, config: EstimatorConfig, timing: dict[str, Any]
) -> tuple[dict[str, Any], list[AllanCurve]]:
    """The IMU's quantisation, its floors against the configured densities, and the Allan deviation (module
    doc). Densities in deg/h/sqrt(Hz) and micro-g/sqrt(Hz)."""
    rate = float(timing.get("rate_hz", math.nan))
    if not len(log.imu.t) or not np.isfinite(rate):
        raise GtsamDvlError(
            f"{log.source or 'the log'}: fewer than two IMU samples with increasing stamps: "
            "nothing to characterise"
        )
    gyro_q, accel_q = imu_quantisation(np.asarray(log.imu.b_omega), np.asarray(log.imu.b_f))
    out: dict[str, Any] = {}
    for name, steps, per, unit, key in (
        ("gyro", gyro_q, DEG_PER_H, "rad/s", "gyro_noise_deg_per_h_rthz"),
        ("accel", accel_q, UG, "m/s^2", "accel_noise_ug_rthz"),
    ):
        floors = [
            None if not np.isfinite(q) else quantisation_density(float(q), rate) / per
            for q in steps
        ]
        x = np.asarray(log.imu.b_omega if name == "gyro" else log.imu.b_f, dtype=float)
        repeats = (np.diff(x, axis=0) == 0).mean(axis=0) if len(x) > 1 else np.zeros(3)
        out[name] = {
            "step": [None if not np.isfinite(q) else float(q) for q in steps],
            "step_unit": unit,
            "floor_density": floors,
            "configured_density": float(getattr(config.imu, key)),
            "density_unit": "deg/h/sqrt(Hz)" if name == "gyro" else "micro-g/sqrt(Hz)",
            "repeat_fraction": repeats.tolist(),
        }
        for k, (q, rep) in enumerate(zip(steps, repeats, strict=True)):
            if np.isfinite(q) and rep > STUCK_FRACTION:
                out.setdefault("warnings", []).append(
                    f"{name} {AXES[k]}: {rep:.0%} of the samples repeat the previous one (on average "
                    f"{1.0 / max(1.0 - rep, 1e-9):.0f} in a row): the signal does not sweep its quantisation "
                    f"steps, so the rounding error is a slowly changing bias of up to q/2 = "
                    f"{0.5 * q / per:.3g} {'deg/h' if name == 'gyro' else 'micro-g'}, not the white floor"
                )
    stretches = static_stretches(log, rate)
    span = stretches[0] if stretches else None
    allan: dict[str, Any] = {
        "on": "static" if span else "whole log",
        "span_s": list(span) if span else None,
        "static_stretches_s": [list(s) for s in stretches],
    }
    if span is None:
        allan["warning"] = (
            f"no static stretch of {MIN_STATIC_S:.0f} s or more: Allan deviation over the whole "
            "log, where the motion dominates all but the shortest averaging times (its white "
            "density is an upper bound, its bias instability meaningless)"
        )
    curves = allan_curves(log, rate, span)
    t = np.asarray(log.imu.t, dtype=float)
    sel = np.ones(len(t), bool) if span is None else (t >= span[0]) & (t <= span[1])
    for name in ("gyro", "accel"):
        allan[name] = [c.as_dict() for c in curves if c.sensor == name]
        # at rest an axis that scatters over fewer than STATIC_MIN_STEPS steps shows its rounding, not its noise
        # (estimators/models/noise_levels.py leaves such axes out of the static density the same way)
        x = np.asarray(log.imu.b_omega if name == "gyro" else log.imu.b_f, dtype=float)[sel]
        for k, entry in enumerate(allan[name]):
            q = out[name]["step"][k]
            entry["dominated_by_quantisation"] = bool(
                q is not None and np.std(x[:, k]) < STATIC_MIN_STEPS * q
            )
        if any(c.white_density is None for c in curves if c.sensor == name):
            allan.setdefault("notes", []).append(
                f"{name}: an axis never left its quantisation level on the stretch (its Allan deviation is zero): "
                "the quantisation hides the sensor's noise there"
            )
    out["allan"] = allan
    return out, curves


def dvl_section(log: LogData, config: EstimatorConfig, progress: Any = None) -> dict[str, Any]:
    """The batch smoother with the DVL noise fit on (module doc): the fitted ping sigma, chi^2/dof, the DVL
    residuals' autocorrelation and their white plus Gauss-Markov fit. Sigmas in m/s, times in s."""
    from gtsam_dvl.analysis.health import dvl_residuals
    from gtsam_dvl.estimators.run import run_trajectory_estimator

    # the DVL's level started at the lowest the fit allows: the smoother holds a fitted level at the stated one
    # (estimators/models/noise_levels.py honest_multiplier), and this command measures what the data show, not what was
    # stated (the multiplier reported is still on the stated level)
    start = config.noise.dvl_min_multiplier
    fit_config = _noise_fit_config(config, start)
    result = run_trajectory_estimator(log, "batch", fit_config, progress=progress, timeline=False)
    noise = result.info.get("noise", {}).get("dvl", {})
    solver = result.info.get("solver", {})
    # the ping scatter (the white fit) is what this command measures; the level the smoother used (held at the
    # stated one, or raised to the 30-60 s means: estimators/models/noise_levels.py honest_multiplier) is reported
    # beside it,
    # and the recommendation takes the larger of the scatter and the 30-60 s means (what the data show at both scales)
    white = noise.get("white_sigma", noise.get("sigma_m_s"))
    stated = None if noise.get("stated_sigma") is None else noise["stated_sigma"] / start
    long = (noise.get("long") or {}).get("sigma")
    out: dict[str, Any] = {
        "fit": noise,
        "fitted_sigma_m_s": white,
        "multiplier": (white / stated) if white is not None and stated else noise.get("multiplier"),
        "used_sigma_m_s": noise.get("sigma_m_s"),
        "long_sigma_m_s": long,
        "recommended_sigma_m_s": None if white is None else max(white, long or 0.0),
        "at_bound": bool(noise.get("at_bound", False)),
    }
    dof = solver.get("dof")
    out["chi2_per_dof"] = (2.0 * float(solver["final_error"]) / int(dof)) if dof else None
    # the levels the smoother used (the fitted DVL factor among them)
    used = result.noise_config or fit_config
    res = dvl_residuals(result, log, used.dvl)
    out["dvl_chi2_per_dof"] = res.rms() ** 2 if res.dof.sum() > 0 else None
    out["use_beams"] = used.dvl.use_beams
    r = res.residual_m_s
    if r is None:
        out["residuals"] = {"note": "beam factors: the 3-D velocity residuals are not formed"}
        return out
    ok = np.isfinite(r).all(axis=1)
    t, r = res.t[ok], r[ok]
    timing = stream_timing(np.asarray(log.dvl.t, dtype=float))
    period = float(timing.get("period_s", math.nan))
    residuals: dict[str, Any] = {
        "pings": int(ok.sum()),
        "rms_m_s": np.sqrt(np.mean(r**2, axis=0)).tolist(),
    }
    if len(t) >= 20 and np.isfinite(period):
        residuals.update(_residual_correlation(t, r, period, out))
    out["residuals"] = residuals
    return out


def _noise_fit_config(config: EstimatorConfig, start: float) -> EstimatorConfig:
    """The configuration of dvl_section's run: the noise fitted from the data (the DVL's among it, the IMU's
    quantisation modelled), the DVL's level started at `start` times the stated one."""
    return config.model_copy(
        update={
            "noise": config.noise.model_copy(
                update={"from_data": True, "fit_dvl": True, "imu_quantisation": True}
            ),
            "dvl": config.dvl.model_copy(
                update={"noise_multiplier": start * config.dvl.noise_multiplier}
            ),
        }
    )


def _residual_correlation(
    t: np.ndarray, r: np.ndarray, period: float, out: dict[str, Any]
) -> dict[str, Any]:
    """The DVL residuals' autocorrelation and their white plus Gauss-Markov fit (period: the DVL's, s); a
    warning into out["warnings"] when a correlated error dominates."""
    lags = min(max(AUTOCORR_LAGS, int(round(AUTOCORR_SPAN_S / period))), len(t) // 4)
    c, pairs = autocovariance(t, r - r.mean(axis=0), period, lags)
    residuals: dict[str, Any] = {}
    residuals["autocorrelation"] = {
        "lag_s": (np.arange(lags + 1) * period).tolist(),
        "rho": (c / c[0]).tolist() if c[0] > 0 else None,
        "pairs": pairs.tolist(),
    }
    gm = gauss_markov_fit(t, r, period)
    residuals["gauss_markov"] = {
        "white_sigma_m_s": gm.white_sigma,
        "gm_sigma_m_s": gm.gm_sigma,
        "gm_tau_s": gm.gm_tau_s,
        "significant": gm.significant,
        "gm_sigma_noise_m_s": gm.gm_sigma_noise,
        "samples": gm.samples,
    }
    if gm.significant and gm.gm_sigma > gm.white_sigma:
        out["warnings"] = [
            f"the DVL residuals are mostly a correlated error ({gm.gm_sigma * 1e3:.3g} mm/s over "
            f"{gm.gm_tau_s:.3g} s against {gm.white_sigma * 1e3:.3g} mm/s white): a bottom-track error of the "
            "DVL, or a model error of the smoother (a wrong initial attitude or mounting, a gyro whose "
            "quantisation acts as a bias); the fitted noise then measures that error too"
        ]
    return residuals


def _sig(v: float, digits: int = 3) -> float:
    return float(f"{v:.{digits}g}")


def recommend(config: EstimatorConfig, imu: dict[str, Any], dvl: dict[str, Any]) -> dict[str, Any]:
    """The recommended [imu] densities and [dvl] sigma, each with why (module doc)."""
    rec: dict[str, Any] = {"imu": {}, "dvl": {}, "noise": {}, "why": []}
    static = imu["allan"]["on"] == "static"
    for name, key, unit in (
        ("gyro", "gyro_noise_deg_per_h_rthz", "deg/h/sqrt(Hz)"),
        ("accel", "accel_noise_ug_rthz", "micro-g/sqrt(Hz)"),
    ):
        entry = imu[name]
        configured = entry["configured_density"]
        floors = [f for f in entry["floor_density"] if f is not None]
        value, why = configured, f"{name}: not quantised, the configured {configured:.3g} {unit}"
        if floors:
            value = math.hypot(configured, max(floors))
            why = (
                f"{name}: quantised, floor {max(floors):.3g} {unit}: {value:.3g} (configured {configured:.3g} "
                "and the floor, root sum of squares)"
            )
        measured = [
            a["white_density"]
            for a in imu["allan"][name]
            if a["white_density"] is not None and not a.get("dominated_by_quantisation")
        ]
        if static and measured and max(measured) > STATIC_RAISE_FACTOR * value:
            value = max(measured)
            why += f"; the static Allan deviation's white density is higher: {value:.3g}"
        rec["imu"][key] = _sig(value)
        rec["why"].append(why)
    if any(f is not None for n in ("gyro", "accel") for f in imu[n]["floor_density"]):
        rec["noise"]["imu_quantisation"] = False
    sigma = dvl.get("recommended_sigma_m_s", dvl.get("fitted_sigma_m_s"))
    if sigma is not None and np.isfinite(sigma) and not dvl.get("at_bound"):
        key = "beam_noise_m_s" if dvl.get("use_beams") else "noise_m_s"
        rec["dvl"][key] = _sig(float(sigma))
        # the sigma is a beam's: only with the beam factors it was fitted with (which
        if dvl.get("use_beams"):
            rec["dvl"]["use_beams"] = True  # take no time offset)
            rec["dvl"]["estimate_time_offset"] = False
        rec["why"].append(
            f"DVL: {sigma * 1e3:.3g} mm/s per {'beam' if dvl.get('use_beams') else 'axis'}, the larger "
            f"of the ping scatter ({dvl['fitted_sigma_m_s'] * 1e3:.3g} mm/s, factor "
            f"{dvl.get('multiplier', 1.0):.3g} on the stated) and the level its 30-60 s means show"
        )
        gm = (dvl.get("residuals") or {}).get("gauss_markov")
        # the estimators then carry it as a state (estimators/models/correlated.py)
        if gm and gm["significant"]:
            rec["dvl"]["correlated_sigma_m_s"] = _sig(float(gm["gm_sigma_m_s"]))
            rec["dvl"]["correlated_tau_s"] = _sig(float(gm["gm_tau_s"]))
            rec["why"] += [
                f"DVL: the residuals hold a correlated (Gauss-Markov) error of "
                f"{gm['gm_sigma_m_s'] * 1e3:.3g} mm/s (a lower bound: the smoother's states absorb its "
                "slow part)",
                f"its time constant, {gm['gm_tau_s']:.3g} s",
            ]
    else:
        rec["why"].append(
            "DVL: no usable noise fit (too few pings, or at a bound of [noise]): left as configured"
        )
    return rec


def recommended_toml(rec: dict[str, Any], log_name: str) -> str:
    """recommended.toml: the [imu], [dvl] (and [noise]) values with a comment on each."""
    lines = [
        f"# Noise levels recommended by `gtsam-dvl characterise` for {log_name}.",
        "# Use: gtsam-dvl smooth LOG -c recommended.toml (or copy these tables into your configuration).",
        "",
    ]
    why = iter(rec["why"])
    lines.append("[imu]")
    for key, value in rec["imu"].items():
        lines += [f"# {next(why)}", f"{key} = {value!r}"]
    lines += ["", "[dvl]"]
    for key, value in rec["dvl"].items():
        if isinstance(value, bool):
            lines.append(f"{key} = {str(value).lower()}")
        else:
            lines += [f"# {next(why)}", f"{key} = {value!r}"]
    if not rec["dvl"]:
        lines.append(f"# {next(why)}")
    if rec["noise"]:
        lines += [
            "",
            "[noise]",
            "# the quantisation floor is already in [imu]: not added a second time",
            "imu_quantisation = false",
        ]
    return "\n".join(lines) + "\n"


@dataclass
class Characterisation:
    """What characterise found (data: characterise.json), the TOML it recommends, the files written."""

    data: dict[str, Any]
    toml: str
    curves: list[AllanCurve] = field(default_factory=list)
    written: list[Path] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The console report."""
        d = self.data
        out = [f"{d['log']}: {d['streams']['imu'].get('duration_s', 0.0):.0f} s"]
        out += _stream_lines(d["streams"])
        out += _imu_lines(d["imu"])
        out += _dvl_lines(d["dvl"])
        rec = d["recommended"]
        out.append(
            "  recommended: "
            + ", ".join(
                f"{k} = {v:g}"
                for sec in ("imu", "dvl")
                for k, v in rec[sec].items()
                if not isinstance(v, bool)
            )
        )
        out += [f"  wrote {p}" for p in self.written]
        return out

    def describe(self) -> str:
        return "\n".join(self.lines())


def _stream_lines(streams: dict[str, Any]) -> list[str]:
    """characterise's lines per sensor stream: its rate, stamp jitter and gaps."""
    out: list[str] = []
    for name, s in streams.items():
        if "rate_hz" not in s:
            out.append(f"  {name:<5} {s['messages']} messages")
            continue
        gaps = (
            f"{s['gaps']} gap{'s' if s['gaps'] > 1 else ''} ({s['gap_lost_s']:.1f} s lost, longest "
            f"{s['longest_gap_s']:.2f} s)"
            if s["gaps"]
            else "no gaps"
        )
        out.append(
            f"  {name:<5} {s['rate_hz']:.2f} Hz, {s['messages']} messages, stamp jitter "
            f"{s['jitter_std_s'] * 1e3:.2f} ms std (max {s['jitter_max_s'] * 1e3:.2f} ms), {gaps}"
        )
    return out


def _imu_lines(imu: dict[str, Any]) -> list[str]:
    """characterise's lines on the IMU: each sensor's quantisation and the white-noise floor it sets, the
    warnings, then the Allan deviation's white noise and bias instability per axis."""
    out: list[str] = []
    for name in ("gyro", "accel"):
        e = imu[name]
        if all(q is None for q in e["step"]):
            out.append(
                f"  {name}: not quantised (configured {e['configured_density']:.3g} {e['density_unit']})"
            )
            continue
        steps = ", ".join("-" if q is None else f"{q:.3g}" for q in e["step"])
        floors = ", ".join("-" if f is None else f"{f:.3g}" for f in e["floor_density"])
        out.append(
            f"  {name} quantised at {steps} {e['step_unit']} (x, y, z): white-noise floor {floors} "
            f"{e['density_unit']} against the configured {e['configured_density']:.3g}"
        )
    out += [f"  warning: {w}" for w in imu.get("warnings", [])]
    return out + _allan_lines(imu["allan"])


def _allan_lines(allan: dict[str, Any]) -> list[str]:
    """characterise's lines on the Allan deviation: white noise and bias instability per sensor and axis."""
    out: list[str] = []
    where = (
        f"on the static stretch {allan['span_s'][0]:.0f}-{allan['span_s'][1]:.0f} s"
        if allan["span_s"]
        else "on the whole log"
    )
    for name, unit in (("gyro", "deg/h"), ("accel", "micro-g")):
        white = ", ".join(
            "-" if a["white_density"] is None else f"{a['white_density']:.3g}" for a in allan[name]
        )
        bias = ", ".join(
            "-"
            if a["bias_instability"] is None
            else f"{'<' if a['bias_instability_is_upper_bound'] else ''}{a['bias_instability']:.3g}"
            for a in allan[name]
        )
        out.append(
            f"  Allan {name} {where}: white {white} {unit}/sqrt(Hz), bias instability {bias} {unit}"
        )
    out += [f"  warning: {allan['warning']}"] if "warning" in allan else []
    out += [f"  note: {n}" for n in allan.get("notes", [])]
    return out


def _dvl_lines(dvl: dict[str, Any]) -> list[str]:
    """characterise's lines on the DVL: its fitted noise, chi^2/dof, the residuals' autocorrelation and their
    white plus Gauss-Markov fit, the warnings."""
    out: list[str] = []
    if dvl.get("fitted_sigma_m_s") is not None:
        chi = dvl.get("chi2_per_dof")
        out.append(
            f"  DVL noise fitted: {dvl['fitted_sigma_m_s'] * 1e3:.3g} mm/s (factor "
            f"{dvl['multiplier']:.3g} on the stated); chi^2/dof "
            f"{'-' if chi is None else f'{chi:.2f}'} (DVL rows {dvl['dvl_chi2_per_dof']:.2f})"
        )
    else:
        out.append(f"  DVL: {dvl['fit'].get('why', 'no noise fit')}")
    res = dvl.get("residuals", {})
    auto = res.get("autocorrelation", {})
    rho, lag_s = auto.get("rho"), auto.get("lag_s")
    if rho:
        shown = sorted({k for k in (1, 5, 10, 30) if k < len(rho)} | {len(rho) - 1})
        out.append(
            "  DVL residual autocorrelation at lag "
            + ", ".join(f"{lag_s[k]:.3g} s: {rho[k]:+.2f}" for k in shown)
        )
    gm = res.get("gauss_markov")
    if gm:
        out.append(
            f"  DVL residuals: white {gm['white_sigma_m_s'] * 1e3:.3g} mm/s + Gauss-Markov "
            f"{gm['gm_sigma_m_s'] * 1e3:.3g} mm/s, time constant {gm['gm_tau_s']:.3g} s ("
            + ("significant" if gm["significant"] else "not significant: white noise explains them")
            + ")"
        )
    out += [f"  warning: {w}" for w in dvl.get("warnings", [])]
    return out


def characterise_log(
    log: LogData, config: EstimatorConfig, progress: Any = None, name: str = ""
) -> Characterisation:
    """Characterise the sensors of a log (module doc); no file is written."""
    streams: dict[str, dict[str, Any]] = {
        "imu": stream_timing(log.imu.t),
        "dvl": stream_timing(log.dvl.t),
    }
    streams["dvl"]["valid_fraction"] = float(np.mean(log.dvl.valid)) if len(log.dvl) else 0.0
    if log.depth is not None:
        streams["depth"] = stream_timing(log.depth.t)
    if log.gnss is not None:
        streams["gnss"] = stream_timing(log.gnss.t)
    imu, curves = imu_section(log, config, streams["imu"])
    dvl = dvl_section(log, config, progress)
    rec = recommend(config, imu, dvl)
    data = {
        "log": name or log.source,
        "streams": streams,
        "imu": imu,
        "dvl": dvl,
        "recommended": rec,
        "config": config.to_dict(),
    }
    return Characterisation(data, recommended_toml(rec, Path(name or log.source).name), curves)


def characterise_to_dir(
    log_path: Path,
    out_dir: Path,
    config_path: Path | None = None,
    force: bool = False,
    show_progress: bool = True,
    read_options: ReadOptions | None = None,
) -> Characterisation:
    """`gtsam-dvl characterise`: read the log, characterise it, write DIR/characterise.json, allan.png and
    recommended.toml all together (or none). A DIR that exists and holds files is refused unless force; an
    output that is an input is refused before any work."""
    from gtsam_dvl.app.commands import load_log
    from gtsam_dvl.app.outputs import check_outputs
    from gtsam_dvl.app.plots.noise_plots import allan_png
    from gtsam_dvl.app.progress import progress_bar
    from gtsam_dvl.io.atomic import OutputSet

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise GtsamDvlError(f"{out_dir}: -o is a file, not a folder")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not force:
        raise GtsamDvlError(
            f"{out_dir}: the folder exists and is not empty; give --force to write "
            f"{', '.join(OUTPUT_FILES)} into it (they are replaced)"
        )
    check_outputs(
        {"the input log": Path(log_path), "the configuration": config_path},
        {f"-o {name}": out_dir / name for name in OUTPUT_FILES},
    )
    config = EstimatorConfig.load(config_path) if config_path else None
    with progress_bar(f"reading {Path(log_path).name}", enabled=show_progress) as read_progress:
        log = load_log(log_path, read_options, progress=read_progress)
    if config is None:
        config = EstimatorConfig.for_log(log.metadata)
    with progress_bar(f"characterising {Path(log_path).name}", enabled=show_progress) as progress:
        ch = characterise_log(log, config, progress=progress, name=str(log_path))
    imu = ch.data["imu"]
    rate = float(ch.data["streams"]["imu"]["rate_hz"])
    png = allan_png(
        ch.curves,
        {n: imu[n]["configured_density"] for n in ("gyro", "accel")},
        {
            n: [None if q is None else quantisation_density(q, rate) / per for q in imu[n]["step"]]
            for n, per in (("gyro", DEG_PER_H), ("accel", UG))
        },
        title=f"Allan deviation, {Path(log_path).name} ({imu['allan']['on']})",
    )
    outputs = OutputSet()
    with outputs:
        outputs.write_json(out_dir / "characterise.json", ch.data)
        outputs.write_bytes(out_dir / "allan.png", png)
        outputs.write_text(out_dir / "recommended.toml", ch.toml)
    ch.written = outputs.committed
    return ch
