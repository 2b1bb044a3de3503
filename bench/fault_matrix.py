"""The fault matrix: what real logs contain, injected into a simulated run, through every estimator.

For each case (a fault injected into paper-3d, seed 11, or a log written to MCAP and damaged) and each mode
(batch, online, ekf) it prints: the outcome (ok: an estimate; error: the one-line GtsamDvlError a user sees;
CRASH: any other exception, a bug), the health status of the run, the largest |error / sigma| of the
calibration and biases, and the final horizontal position error (m and in sigmas). A silent wrong answer is an
estimate with health "ok" and some error beyond 3 sigma: the script counts them and exits 1 if there is any.

    python bench/fault_matrix.py [--cases a,b,...] [--modes batch,online,ekf] [--scenario paper-3d] [--config paper]

The whole matrix takes minutes per mode (docs/results.md, "Faulty logs"); tests/test_fault_matrix.py runs a short
subset.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

MODES: dict[str, Callable[[LogData, EstimatorConfig], object]] = {
    "batch": smooth_batch,
    "online": smooth_online,
    "ekf": run_ekf,
}
SEED = 11


def _replace_dvl(log: LogData, **kw: object) -> LogData:
    return dataclasses.replace(log, dvl=dataclasses.replace(log.dvl, **kw))


def _without_imu(log: LogData, t0: float, t1: float) -> LogData:
    keep = (log.imu.t <= t0) | (log.imu.t > t1)
    imu = dataclasses.replace(
        log.imu, t=log.imu.t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
    )
    return dataclasses.replace(log, imu=imu)


def _outliers(log: LogData, fraction: float) -> LogData:
    rng = np.random.default_rng(3)
    d_v = log.dvl.d_v.copy()
    hit = np.flatnonzero((rng.random(len(d_v)) < fraction) & (log.dvl.t > 610.0))
    direction = rng.normal(size=(len(hit), 3))
    d_v[hit] += (
        direction
        / np.linalg.norm(direction, axis=1)[:, None]
        * rng.uniform(0.5, 2.0, (len(hit), 1))
    )
    return _replace_dvl(log, d_v=d_v)


def _zero_dvl(log: LogData, t0: float, t1: float) -> LogData:
    d_v = log.dvl.d_v.copy()
    d_v[(log.dvl.t > t0) & (log.dvl.t < t1)] = 0.0
    return _replace_dvl(log, d_v=d_v)


def _dropout(log: LogData, t0: float, t1: float) -> LogData:
    return _replace_dvl(log, valid=log.dvl.valid & ~((log.dvl.t > t0) & (log.dvl.t < t1)))


def _rolled_imu(log: LogData) -> LogData:
    b_R_imu = rpy_deg_to_matrix([180.0, 0.0, 0.0])
    imu = dataclasses.replace(log.imu, b_omega=log.imu.b_omega @ b_R_imu, b_f=log.imu.b_f @ b_R_imu)
    return dataclasses.replace(
        log, imu=imu, mounting=dataclasses.replace(log.mounting, b_R_imu=b_R_imu)
    )


def _fast_static_ping(log: LogData, t: float) -> LogData:
    d_v = log.dvl.d_v.copy()
    d_v[int(np.searchsorted(log.dvl.t, t))] = [0.8, 0.0, 0.0]
    return _replace_dvl(log, d_v=d_v)


def _through_file(log: LogData, damage: Callable[[Path], None], **read: object) -> LogData:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.mcap"
        write_log(path, log)
        damage(path)
        return read_log(path, **read)  # type: ignore[arg-type]


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])


def _flip(path: Path) -> None:
    """A flipped byte in the middle of the file (in paper-3d's it lands in a MessageIndex record)."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _flip_in_chunk(path: Path) -> None:
    """A flipped byte inside the compressed data of a chunk in the middle of the file (its CRC fails)."""
    from gtsam_dvl.io.mcap.scan import McapScan

    chunks = [s for s in McapScan(path).segments if not isinstance(s, list)]
    mid = chunks[len(chunks) // 2].data
    data = bytearray(path.read_bytes())
    data[(mid.start + mid.stop) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _nan_samples(log: LogData) -> LogData:
    imu = dataclasses.replace(log.imu, b_f=log.imu.b_f.copy())
    n, m = len(log.imu), len(log.dvl)
    imu.b_f[[n // 3, 2 * n // 3]] = np.nan
    d_v = log.dvl.d_v.copy()
    d_v[m // 2] = np.inf
    return dataclasses.replace(_replace_dvl(log, d_v=d_v), imu=imu)


def _backwards(log: LogData) -> LogData:
    t = log.imu.t.copy()
    t[len(t) // 2] = t[len(t) // 2 - 10]
    return dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=t))


def _duplicates(log: LogData) -> LogData:
    t = log.imu.t.copy()
    t[len(t) // 3 + 1] = t[len(t) // 3]
    return dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=t))


def _clock_step(log: LogData, t: float, step_s: float) -> LogData:
    """The IMU's stamps step_s ahead from t on, the samples running on (the IMU's clock jumped)."""
    stamps = log.imu.t.copy()
    stamps[int(np.searchsorted(stamps, t)) :] += step_s
    return dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=stamps))


def _saturated_gyro(base: LogData, limit_rad_s: float) -> LogData:
    """The same run with the gyro's range +-limit_rad_s (the simulator clips every axis there)."""
    raw = dict(base.metadata["scenario"])
    raw["imu"] = {**raw.get("imu", {}), "saturation_gyro_rad_s": limit_rad_s}
    return simulate(scenario_from_dict(raw), SEED)


def _frozen_dvl(log: LogData, t0: float, t1: float) -> LogData:
    """The DVL's output frozen on the ping at t0 until t1."""
    d_v = log.dvl.d_v.copy()
    d_v[(log.dvl.t > t0) & (log.dvl.t <= t1)] = d_v[int(np.searchsorted(log.dvl.t, t0))]
    return _replace_dvl(log, d_v=d_v)


def _mounting_off(log: LogData, yaw_deg: float) -> LogData:
    """The DVL's mounting in /tf_static (b_R_d0) off by yaw_deg about body z; the DVL's data unchanged."""
    b_R_d0 = rpy_deg_to_matrix([0.0, 0.0, yaw_deg]) @ np.asarray(log.mounting.b_R_d0, dtype=float)
    return dataclasses.replace(log, mounting=dataclasses.replace(log.mounting, b_R_d0=b_R_d0))


def _dvl_late(log: LogData, late_s: float) -> LogData:
    """The DVL's stamps late_s late (each ping measured the velocity late_s before its stamp)."""
    return _replace_dvl(log, t=log.dvl.t + late_s)


def _water_track(log: LogData, t0: float, t1: float) -> LogData:
    """The DVL in water-track mode from t0 to t1 (its pings marked so, not valid as velocity over ground)."""
    water = (log.dvl.t >= t0) & (log.dvl.t < t1)
    return _replace_dvl(log, valid=log.dvl.valid & ~water, water_track=water)


def _static_only(base: LogData) -> LogData:
    raw = dict(base.metadata["scenario"])
    raw["segments"] = [{"kind": "static", "duration_s": 300.0}]
    return simulate(scenario_from_dict(raw), SEED)


def _dvl_rate(base: LogData, hz: float) -> LogData:
    raw = dict(base.metadata["scenario"])
    raw["rates"] = {**raw.get("rates", {}), "dvl_hz": hz}
    return simulate(scenario_from_dict(raw), SEED)


def cases(base: LogData) -> dict[str, Callable[[], LogData]]:
    """The faults, placed by the run's own segments: the middle of the first turn of the square, the straight
    leg after it, the static phase's middle."""
    square = next(seg for seg in base.segments if seg.kind == "square")
    static = base.segments[0]
    turn, leg = square.start_s + 30.0, square.start_s + 90.0
    long_dropout = min(600.0, square.end_s - square.start_s - 200.0)
    return {
        "clean": lambda: base,
        "imu_gap_1s_straight": lambda: _without_imu(base, leg, leg + 1.0),
        "imu_gap_5s_turn": lambda: _without_imu(base, turn, turn + 5.0),
        "imu_gap_30s_turn": lambda: _without_imu(base, turn, turn + 30.0),
        "dvl_outliers_1pct": lambda: _outliers(base, 0.01),
        "dvl_outliers_5pct": lambda: _outliers(base, 0.05),
        "dvl_zero_30s_moving": lambda: _zero_dvl(base, leg + 60.0, leg + 90.0),
        "dvl_dropout_60s": lambda: _dropout(base, static.end_s + 40.0, static.end_s + 100.0),
        "dvl_dropout_long": lambda: _dropout(base, leg + 60.0, leg + 60.0 + long_dropout),
        "imu_rolled_180_with_tf": lambda: _rolled_imu(base),
        "fast_ping_in_static_phase": lambda: _fast_static_ping(base, 0.5 * static.end_s),
        "truncated_salvaged": lambda: _through_file(base, _truncate, salvage=True),
        "flipped_byte_salvaged": lambda: _through_file(base, _flip, salvage=True),
        "flipped_byte_not_salvaged": lambda: _through_file(base, _flip),
        "corrupt_chunk_salvaged": lambda: _through_file(base, _flip_in_chunk, salvage=True),
        "corrupt_chunk_not_salvaged": lambda: _through_file(base, _flip_in_chunk),
        "nan_inf_repaired": lambda: _through_file(_nan_samples(base), lambda p: None, repair=True),
        "nan_inf_not_repaired": lambda: _through_file(_nan_samples(base), lambda p: None),
        "time_backwards_repaired": lambda: _through_file(
            _backwards(base), lambda p: None, repair=True
        ),
        "duplicate_stamps_repaired": lambda: _through_file(
            _duplicates(base), lambda p: None, repair=True
        ),
        "missing_dvl_topic": lambda: _through_file(
            base, lambda p: None, dvl_topic="/no/such/topic"
        ),
        "static_only": lambda: _static_only(base),
        "dvl_5hz": lambda: _dvl_rate(base, 5.0),
        # read through the file: the reader finds the IMU's faults (core/imu_faults.py)
        "imu_clock_step_5s_turn_repaired": lambda: _through_file(
            _clock_step(base, turn - 15.0, 5.0), lambda p: None, repair=True
        ),
        "imu_clock_step_5s_turn": lambda: _through_file(
            _clock_step(base, turn - 15.0, 5.0), lambda p: None
        ),
        "gyro_saturated_in_turns": lambda: _through_file(
            _saturated_gyro(base, 0.055), lambda p: None
        ),
        "gyro_saturated_long": lambda: _through_file(_saturated_gyro(base, 0.05), lambda p: None),
        "dvl_frozen_40s_turn": lambda: _frozen_dvl(base, turn - 20.0, turn + 20.0),
        "dvl_water_track_20s": lambda: _through_file(
            _water_track(base, leg + 20.0, leg + 40.0), lambda p: None
        ),
        "tf_static_yaw_off_25deg": lambda: _mounting_off(base, 25.0),
        "dvl_stamps_late_2s": lambda: _dvl_late(base, 2.0),
    }


def evaluate(log: LogData, mode: str, config: str = "paper") -> dict[str, object]:
    res = MODES[mode](log, EstimatorConfig.named(config))
    health = assess_health(res, log)  # type: ignore[arg-type]
    s = summary(res, log)  # type: ignore[arg-type]
    e = s.get("errors") or {}
    nsig = [
        abs(e.get("scale_nsigma", 0.0)),
        *np.abs(e.get("misalignment_nsigma", [0.0])),
        *np.abs(e.get("gyro_bias_nsigma", [0.0])),
        *np.abs(e.get("accel_bias_nsigma", [0.0])),
    ]
    pos = e.get("final_horizontal_position_m")
    pos_sig = s["final_horizontal_position_sigma_m"]
    return {
        "outcome": "ok",
        "health": health.status,
        "worst_nsigma": float(np.nanmax(nsig)) if e else float("nan"),
        "final_m": pos,
        "final_nsigma": (pos / pos_sig) if pos is not None and pos_sig else float("nan"),
        "warnings": len(health.warnings),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="")
    ap.add_argument("--modes", default="batch,online,ekf")
    ap.add_argument("--scenario", default="paper-3d")
    ap.add_argument(
        "--config",
        default="paper",
        help="the named configuration of the estimators (paper, default)",
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    base = simulate(load_scenario(args.scenario), SEED)
    todo = cases(base)
    names = args.cases.split(",") if args.cases else list(todo)
    modes = args.modes.split(",")
    print(
        f"{'case':28s} {'mode':7s} {'outcome':8s} {'health':9s} {'max|err/sig|':>12s} {'final pos':>14s}  note"
    )
    silent = crashes = 0
    for name in names:
        try:
            log = todo[name]()
            load_error = None
        except GtsamDvlError as exc:
            log, load_error = None, str(exc)
        except Exception as exc:  # a crash is a bug: reported, not hidden
            log, load_error = None, f"CRASH {type(exc).__name__}: {exc}"
        for mode in modes:
            if log is None:
                outcome = "CRASH" if load_error and load_error.startswith("CRASH") else "error"
                crashes += outcome == "CRASH"
                print(
                    f"{name:28s} {mode:7s} {outcome:8s} {'-':9s} {'-':>12s} {'-':>14s}  {load_error[:90]}"
                )
                continue
            try:
                r = evaluate(log, mode, args.config)
            except GtsamDvlError as exc:
                print(
                    f"{name:28s} {mode:7s} {'error':8s} {'-':9s} {'-':>12s} {'-':>14s}  {str(exc)[:90]}"
                )
                continue
            except Exception as exc:
                crashes += 1
                print(
                    f"{name:28s} {mode:7s} {'CRASH':8s} {'-':9s} {'-':>12s} {'-':>14s}  {type(exc).__name__}: {exc}"
                )
                traceback.print_exc(limit=3)
                continue
            wrong = r["health"] == "ok" and (r["worst_nsigma"] > 3 or r["final_nsigma"] > 3)  # type: ignore[operator]
            silent += bool(wrong)
            pos = "-" if r["final_m"] is None else f"{r['final_m']:.1f} m {r['final_nsigma']:.1f}s"
            print(
                f"{name:28s} {mode:7s} {'ok':8s} {r['health']!s:9s} {r['worst_nsigma']:12.2f} {pos:>14s}  "
                f"{'SILENT WRONG ANSWER' if wrong else ''}{r['warnings']} warning(s)"
            )
    print(
        f"\n{len(names)} cases x {len(modes)} modes in {time.perf_counter() - t0:.0f} s: {silent} silent wrong "
        f"answer(s), {crashes} crash(es)"
    )
    return 1 if silent or crashes else 0


if __name__ == "__main__":
    sys.exit(main())
