"""The fault matrix (bench/fault_matrix.py) on a short paper-3d-like run: for every case and mode, a clear error
or an estimate; never a crash, and never a silent wrong answer (health "ok" with a calibration, bias or final
position error beyond 3 sigma). The full matrix on paper-3d runs in the benchmark."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import fault_matrix as fm  # noqa: E402

from gtsam_dvl.core.errors import GtsamDvlError  # noqa: E402
from gtsam_dvl.core.types import LogData  # noqa: E402
from gtsam_dvl.sim import simulate  # noqa: E402
from gtsam_dvl.sim.scenario import load_scenario  # noqa: E402

pytestmark = pytest.mark.slow

# the cases whose right outcome is a clear one-line error, and what it must say; a salvaged corrupt chunk
# leaves a hole of about 24 s in the IMU data, longer than imu.max_gap_s, so it must be named as a gap
EXPECTED_ERRORS = {
    "imu_gap_30s_turn": "IMU gap of 30.0 s",
    "nan_inf_not_repaired": "NaN",
    "missing_dvl_topic": "no DVL topic",
    "corrupt_chunk_not_salvaged": "--salvage",
    "corrupt_chunk_salvaged": "IMU gap of",
}
# the batch smoother cuts a log at IMU gaps longer than imu.max_gap_s and smooths the pieces
# (estimators/batch/pieces.py)
SMOOTHED_AS_PIECES = {"imu_gap_30s_turn", "corrupt_chunk_salvaged", "flipped_byte_salvaged"}
# where a byte in the middle of the file lands depends on the file: in a MessageIndex record nothing is lost
# (the chunk is walked), in a chunk's data it is one of the two errors above
MAY_ERROR = {"flipped_byte_salvaged": "IMU gap of", "flipped_byte_not_salvaged": "--salvage"}


@pytest.fixture(scope="module")
def short_run() -> LogData:
    """paper-3d's manoeuvres, shortened (data/scenarios/paper-3d-short.toml: 120 s static, 60 s legs)."""
    return simulate(load_scenario("paper-3d-short"), fm.SEED)


CASES = [
    "clean",
    "imu_gap_1s_straight",
    "imu_gap_5s_turn",
    "imu_gap_30s_turn",
    "dvl_outliers_1pct",
    "dvl_outliers_5pct",
    "dvl_zero_30s_moving",
    "dvl_dropout_60s",
    "dvl_dropout_long",
    "imu_rolled_180_with_tf",
    "fast_ping_in_static_phase",
    "truncated_salvaged",
    "flipped_byte_salvaged",
    "flipped_byte_not_salvaged",
    "corrupt_chunk_salvaged",
    "corrupt_chunk_not_salvaged",
    "nan_inf_repaired",
    "nan_inf_not_repaired",
    "time_backwards_repaired",
    "duplicate_stamps_repaired",
    "missing_dvl_topic",
    "static_only",
    "dvl_5hz",
]


@pytest.mark.parametrize("case", CASES)
def test_fault_case_is_an_error_or_an_honest_estimate(short_run: LogData, case: str) -> None:
    try:
        log = fm.cases(short_run)[case]()
    except GtsamDvlError as exc:
        assert "\n" not in str(exc)
        expected = EXPECTED_ERRORS.get(case) or MAY_ERROR.get(case)
        assert expected is not None and expected in str(exc), str(exc)
        return
    for mode in fm.MODES:
        try:
            r = fm.evaluate(log, mode)
        except GtsamDvlError as exc:
            assert "\n" not in str(exc)
            expected = EXPECTED_ERRORS.get(case) or MAY_ERROR.get(case)
            assert expected is not None and expected in str(exc), f"{mode}: {exc}"
            continue
        print(
            f"{case} {mode}: health {r['health']}, max |err/sigma| {r['worst_nsigma']:.2f}, final position "
            f"{r['final_nsigma']:.2f} sigma"
        )
        assert case not in EXPECTED_ERRORS or (mode == "batch" and case in SMOOTHED_AS_PIECES), (
            f"{mode}: expected an error"
        )
        honest = r["worst_nsigma"] <= 3.0 and r["final_nsigma"] <= 3.0  # type: ignore[operator]
        if not np.isfinite(r["worst_nsigma"]):  # type: ignore[arg-type]
            honest = r["health"] != "ok"
        assert honest or r["health"] != "ok", f"{mode}: silent wrong answer {r}"
        if case == "clean":
            assert r["health"] == "ok" and honest, f"{mode}: {r}"
