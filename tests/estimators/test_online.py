"""Online (iSAM2) estimator: agreement with the batch smoother, the sigma timeline of the paper's
observability story, and message handling. Every test prints what it measured.

Runs are cached per session and worker: the fixed-lag runs on the full paper logs serve both the agreement and
the timeline tests; the full-history mode runs on paper-3d cut at 1000 s (static, Type-I manoeuvres, the first
turns), which keeps it short (its cost grows with the mission: see bench/bench_online.py).
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult, misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.online import (
    MessageDropped,
    OnlineConfig,
    OnlineEstimator,
    feed_log,
    smooth_online,
)
from gtsam_dvl.estimators.online.types import misalignment_deg_and_cov
from tests.support.logs import cut_log
from tests.support.paper_runs import GROUP, paper_batch, paper_log, paper_online
from tests.support.results import changes_in_sigmas

PRIOR = EstimatorConfig.paper().priors
# the paper runs shared with test_batch.py, test_robust.py
pytestmark = pytest.mark.xdist_group(GROUP)


@functools.cache
def _log(name: str, seed: int, t_end: float | None = None) -> LogData:
    log = paper_log(name, seed)
    return log if t_end is None else cut_log(log, t_end)


@functools.cache
def _batch(
    name: str, seed: int, t_end: float | None = None, bias_model: str = "constant"
) -> NavResult:
    if t_end is None and bias_model == "constant":
        return paper_batch(name, seed)
    cfg = EstimatorConfig.paper()
    cfg.imu.bias_model = bias_model
    return smooth_batch(_log(name, seed, t_end), cfg)


@functools.cache
def _online(
    name: str,
    seed: int,
    mode: str = "fixed_lag",
    t_end: float | None = None,
    bias_model: str = "constant",
) -> NavResult:
    if t_end is None and mode == "fixed_lag" and bias_model == "constant":
        return paper_online(name, seed)
    cfg = EstimatorConfig.paper()
    cfg.imu.bias_model = bias_model
    return smooth_online(_log(name, seed, t_end), cfg, mode=mode)


def _sigma_ratio(online: NavResult, batch: NavResult) -> np.ndarray:
    return np.concatenate(
        [
            [online.scale_sigma / batch.scale_sigma],
            online.misalignment_sigma_deg / batch.misalignment_sigma_deg,
            online.gyro_bias_sigma_deg_per_h / batch.gyro_bias_sigma_deg_per_h,
            online.accel_bias_sigma_ug / batch.accel_bias_sigma_ug,
        ]
    )


def _report(tag: str, online: NavResult, batch: NavResult) -> dict[str, np.ndarray]:
    d = changes_in_sigmas(online, batch)  # online minus batch final estimates, in batch sigmas
    print(
        f"\n{tag}: online - batch in batch sigmas: "
        + "; ".join(f"{k} {np.round(v, 3)}" for k, v in d.items())
    )
    print(
        f"{tag}: sigma online / batch {np.round(_sigma_ratio(online, batch), 3)}; latency ms "
        f"{ {k: round(v, 2) for k, v in online.info['latency_ms'].items()} }; iSAM2 {online.info['isam2']}; "
        f"{online.timing_s['total']:.1f} s for {online.t[-1] - online.t[0]:.0f} s of data"
    )
    return d


# ----- agreement with the batch smoother -----------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "seed"), [("paper-3d", 1), ("paper-3d", 2), ("paper-2d", 1), ("paper-2d", 2)]
)
def test_fixed_lag_agrees_with_batch(name: str, seed: int) -> None:
    """Final scale, misalignment and biases within 1 batch sigma (measured: below 0.2), with the same sigmas
    within 3 %, except the vertical accelerometer bias's, 10 % larger: the static phase's zero-velocity pings left
    the window while the scale was still its prior 0.8, and a ping's information on the velocity is k^2 / sigma^2
    at the scale known then (the batch smoother credits them at its final 1.0)."""
    online, batch = _online(name, seed), _batch(name, seed)
    d = _report(f"{name} seed {seed} fixed-lag", online, batch)
    for key, v in d.items():
        assert np.all(np.abs(v) < 1.0), key
    ratio = _sigma_ratio(online, batch)
    assert np.all(np.abs(ratio[:-1] - 1) < 0.03)
    assert 1.0 <= ratio[-1] < 1.15
    assert online.info["isam2"]["states_marginalized"] > 0.9 * len(online.t)


@pytest.mark.slow
def test_usable_pings_are_the_batch_smoothers() -> None:
    """The usable pings the online estimator records (NavResult.dvl_pings, numbered as pushed: the log's by
    feed_log) are the batch smoother's, ping for ping."""
    online, batch = _online("paper-2d", 1), _batch("paper-2d", 1)
    assert (
        online.dvl_pings is not None and batch.dvl_pings is not None and len(batch.dvl_pings) > 1000
    )
    np.testing.assert_array_equal(online.dvl_pings, batch.dvl_pings)


@pytest.mark.slow
def test_full_history_agrees_with_batch() -> None:
    """paper-3d cut at 1000 s (static, Type I, descent, the first turns): within 0.1 batch sigma (measured:
    0.02), same sigmas within 1 %."""
    online, batch = _online("paper-3d", 1, "full", 1000.0), _batch("paper-3d", 1, 1000.0)
    d = _report("paper-3d 0-1000 s full history", online, batch)
    for key, v in d.items():
        assert np.all(np.abs(v) < 0.1), key
    assert np.all(np.abs(_sigma_ratio(online, batch) - 1) < 0.01)
    assert (
        online.info["isam2"]["states_marginalized"] == 0
        and online.info["isam2"]["variables"] > 2000
    )


@pytest.mark.slow
def test_fixed_lag_timeline_matches_full_history() -> None:
    """The fixed-lag filtering sigmas follow the full-history ones (iSAM2 keeping every state) within 10 % at
    every epoch (measured: 8.5 % at worst, the pitch misalignment near 800 s), and its window stays bounded. What
    the window gives up is relinearising what left it: the static phase's zero-velocity pings left while the
    scale was its prior 0.8 and are credited k^2 / sigma^2 of velocity information at that scale, which the
    full history re-credits at 1.0 once the scale is known (the vertical channel: pitch misalignment and
    vertical accelerometer bias)."""
    lag, full = _online("paper-3d", 1, "fixed_lag", 1000.0), _online("paper-3d", 1, "full", 1000.0)
    a, b = lag.timeline, full.timeline
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.t, b.t)
    worst = {}
    for name in (
        "scale_sigma",
        "misalignment_sigma_deg",
        "gyro_bias_sigma_deg_per_h",
        "accel_bias_sigma_ug",
        "attitude_sigma_deg",
    ):
        ratio = getattr(a, name) / getattr(b, name)
        worst[name] = float(np.max(np.abs(ratio - 1)))
    print(
        f"\nfixed-lag / full-history filtering sigmas, worst |ratio - 1| over 1000 epochs: "
        f"{ {k: round(v, 4) for k, v in worst.items()} }; fixed-lag iSAM2 {lag.info['isam2']}"
    )
    assert max(worst.values()) < 0.10
    window = lag.info["window_s"]
    assert lag.info["isam2"]["variables"] <= 2 * (window + 2) + 3


@pytest.mark.slow
def test_random_walk_bias_fixed_lag_agrees_with_batch() -> None:
    """The bias as a random walk (a bias state per epoch, the newest in the window): paper-3d cut at 900 s."""
    online = _online("paper-3d", 3, "fixed_lag", 900.0, "random_walk")
    batch = _batch("paper-3d", 3, 900.0, "random_walk")
    d = _report("paper-3d 0-900 s random-walk bias, fixed-lag", online, batch)
    for key, v in d.items():
        assert np.all(np.abs(v) < 1.0), key


# ----- the sigma timeline (the paper's observability story) ---------------------------------------


def _at(t: np.ndarray, x: np.ndarray, when: float) -> np.ndarray:
    return np.asarray(x[int(np.searchsorted(t, when))])


@pytest.mark.slow
def test_sigma_timeline_paper_3d() -> None:
    """The sigma timeline's criteria on paper-3d (fixed lag, seed 1).

    A target of the yaw misalignment sigma falling 10x within 60 s of the motion starting is not what these data
    support: with 2 cm/s DVL noise the level acceleration of 600-660 s brings it from 1 deg to 0.14 deg
    (7x); the batch smoother's own filtering timeline (estimators/timeline.filtering_timeline) gives 0.134 deg
    at 660 s too. It passes 10x during the first banked turn, at 813 s. Asserted here: 6x by 660 s, 10x by
    900 s."""
    r = _online("paper-3d", 1)
    tl = r.timeline
    assert tl is not None and len(tl.t) == len(r.t)
    for name, arr in tl.as_arrays().items():
        assert np.all(np.isfinite(arr)), name
    t = tl.t
    s600, s660, s720 = (_at(t, tl.scale_sigma, x) for x in (600, 660, 720))
    m = {x: _at(t, tl.misalignment_sigma_deg, x) for x in (600, 660, 720, 900)}
    a = {x: _at(t, tl.accel_bias_sigma_ug, x) for x in (600, 750, 900)}
    print(
        f"\nscale sigma 600/660/720 s: {s600:.4f} {s660:.5f} {s720:.5f} (/{s600 / s660:.0f} by 660 s)"
    )
    for x, v in m.items():
        print(f"misalignment sigma [roll, pitch, yaw] at {x} s: {np.round(v, 4)} deg")
    yaw_10x = t[np.argmax(tl.misalignment_sigma_deg[:, 2] < 0.1 * m[600][2])]
    print(
        f"fall by 660 s: pitch /{m[600][1] / m[660][1]:.1f}, yaw /{m[600][2] / m[660][2]:.1f} (10x at {yaw_10x:.0f} "
        f"s); roll 660 -> 720 s: /{m[660][0] / m[720][0]:.2f}"
    )
    for x, v in a.items():
        print(f"accelerometer bias sigma at {x} s: {np.round(v, 2)} micro-g")
    assert s600 > 0.9 * PRIOR.scale_sigma and s660 < s600 / 10
    assert m[660][1] < m[600][1] / 10
    assert m[660][2] < m[600][2] / 6 and m[900][2] < m[600][2] / 10
    roll = tl.misalignment_sigma_deg[:, 0]
    assert np.all(roll[t <= 660] > 0.9 * PRIOR.misalignment_sigma_deg[0])
    assert m[720][0] < m[660][0] / 2
    # accelerometer bias: the horizontal axes stay at their prior until the turns start, then fall markedly
    assert np.all(a[750][:2] > 0.9 * EstimatorConfig.paper().imu.accel_bias_sigma_ug)
    assert np.all(a[900][:2] < a[750][:2] / 4)


@pytest.mark.slow
def test_sigma_timeline_paper_2d_roll_unobservable() -> None:
    """Without depth change the misalignment about the thrust axis keeps its prior to the end (Remark 3)."""
    for seed in (1, 2):
        tl = _online("paper-2d", seed).timeline
        assert tl is not None
        roll = tl.misalignment_sigma_deg[:, 0]
        print(
            f"\npaper-2d seed {seed}: roll sigma min {roll.min():.4f} deg (prior {PRIOR.misalignment_sigma_deg[0]}); "
            f"pitch, yaw sigma at the end {np.round(tl.misalignment_sigma_deg[-1, 1:], 4)}"
        )
        assert np.all(roll > 0.9 * PRIOR.misalignment_sigma_deg[0])


# ----- messages -----------------------------------------------------------------------------------


def _short() -> LogData:
    return _log("paper-3d", 4, 700.0)


def _run(log: LogData, **options: object) -> OnlineEstimator:
    est = OnlineEstimator.for_log(log, options=OnlineConfig(**options))  # type: ignore[arg-type]
    feed_log(est, log)
    return est


@functools.cache
def _reference() -> OnlineEstimator:
    return _run(_short())


def _final(est: OnlineEstimator) -> np.ndarray:
    e = est.estimate()
    assert e is not None
    return np.concatenate([[e.scale], e.misalignment_deg, e.accel_bias, e.gyro_bias, e.n_p, e.n_v])


def test_estimate_after_each_epoch() -> None:
    """Nothing before the alignment; then after every DVL epoch a state with covariances."""
    log = _short()
    est = OnlineEstimator.for_log(log)
    t_first = None
    imu, dvl = log.imu, log.dvl
    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start = 0
    for j in range(200):
        done = est.push_imu_batch(
            imu.t[start : ends[j]], imu.b_omega[start : ends[j]], imu.b_f[start : ends[j]]
        )
        start = int(ends[j])
        done += est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j])
        if done and t_first is None:
            t_first = dvl.t[j]
            print(
                f"\nfirst estimate after the ping at {t_first:.0f} s: {done} epochs processed at once"
            )
            assert done > 60
        if t_first is None:
            assert est.estimate() is None
    e = est.estimate()
    assert e is not None and e.t == dvl.t[199]
    for cov in (e.pose_cov, e.vel_cov, e.bias_cov, e.b_R_d_cov, e.calib_cov):
        assert np.all(np.linalg.eigvalsh(cov) > 0)
    # static: slow pings tell nothing
    assert e.scale_sigma == pytest.approx(PRIOR.scale_sigma, rel=1e-3)
    assert np.all(e.attitude_sigma_deg < [0.01, 0.01, 1.0])


@pytest.mark.slow
def test_per_message_and_late_pings_give_the_batch_feed_result() -> None:
    """One push_imu per sample, and DVL pings delivered 0.35 s late (after IMU samples past their stamps, as
    from another topic): the same result as feed_log's batches, to rounding."""
    log, ref = _short(), _reference()
    est = OnlineEstimator.for_log(log)
    imu, dvl = log.imu, log.dvl
    late = dvl.t + 0.35
    j = 0
    for i in range(len(imu)):
        est.push_imu(imu.t[i], imu.b_omega[i], imu.b_f[i])
        while j < len(dvl) and late[j] <= imu.t[i]:
            est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
            j += 1
    for k in range(j, len(dvl)):
        est.push_dvl(dvl.t[k], dvl.d_v[k], dvl.d_cov[k], bool(dvl.valid[k]))
    est.finish()
    diff = np.abs(_final(est) - _final(ref))
    print(
        f"\nper-message, late pings vs batches: {est.epochs} vs {ref.epochs} epochs, "
        f"max |difference| {diff.max():.2e}"
    )
    assert est.epochs == ref.epochs
    np.testing.assert_allclose(_final(est), _final(ref), rtol=1e-9, atol=1e-9)


def test_bad_messages_rejected_with_a_clear_error() -> None:
    log = _short()
    imu = log.imu
    est = OnlineEstimator.for_log(log)
    est.push_imu_batch(imu.t[:100], imu.b_omega[:100], imu.b_f[:100])
    cases = [
        (
            lambda: est.push_imu(imu.t[99], imu.b_omega[99], imu.b_f[99]),
            "repeats the previous stamp",
        ),
        (lambda: est.push_imu(imu.t[50], imu.b_omega[50], imu.b_f[50]), "older than the previous"),
        (lambda: est.push_imu(imu.t[100], [np.nan, 0, 0], imu.b_f[100]), "non-finite value"),
        (lambda: est.push_imu(np.nan, imu.b_omega[100], imu.b_f[100]), "non-finite stamp"),
        (
            lambda: est.push_imu_batch(
                imu.t[[100, 102, 101]], imu.b_omega[100:103], imu.b_f[100:103]
            ),
            "older",
        ),
        (lambda: est.push_imu(imu.t[100], imu.b_omega[100, :2], imu.b_f[100]), "3-vector"),
    ]
    for call, message in cases:
        with pytest.raises(GtsamDvlError, match=message):
            call()
    est.push_dvl(0.5, [0.0, 0.0, 0.0])
    for call, message in [
        (lambda: est.push_dvl(0.5, [0.0, 0.0, 0.0]), "repeats the previous ping"),
        (lambda: est.push_dvl(0.4, [0.0, 0.0, 0.0]), "older than the previous ping"),
        (lambda: est.push_dvl(np.inf, [0.0, 0.0, 0.0]), "non-finite stamp"),
    ]:
        with pytest.raises(GtsamDvlError, match=message):
            call()
    # a ping without bottom lock (NaN velocity) is data, not an error: counted and skipped
    est.push_dvl(0.6, [np.nan, np.nan, np.nan], valid=False)
    print("\nrejected: every bad message raised GtsamDvlError with its stamp")


@pytest.mark.slow
def test_bad_messages_dropped_and_counted() -> None:
    """bad_messages = "drop": duplicates, out-of-order and non-finite samples and pings are dropped, warned
    about once per kind and counted; the estimate is that of the clean stream."""
    log, ref = _short(), _reference()
    imu, dvl = log.imu, log.dvl
    est = OnlineEstimator.for_log(log, options=OnlineConfig(bad_messages="drop"))
    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start = 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for j in range(len(dvl)):
            end = int(ends[j])
            t, w, f = imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end]
            # a duplicated and a stale sample, and a NaN sample, in the batch
            if j % 50 == 7 and len(t) > 3:
                bad_w = w[1].copy()
                bad_w[0] = np.nan
                t = np.concatenate([t[:2], t[1:2], t[:1], [0.5 * (t[1] + t[2])], t[2:]])
                w = np.concatenate([w[:2], w[1:2], w[:1], [bad_w], w[2:]])
                f = np.concatenate([f[:2], f[1:2], f[:1], f[1:2], f[2:]])
            est.push_imu_batch(t, w, f)
            start = end
            est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
            if j % 60 == 11:
                est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j])  # duplicate
                est.push_dvl(dvl.t[j] - 0.5, dvl.d_v[j], dvl.d_cov[j])  # out of order
        est.push_imu_batch(imu.t[start:], imu.b_omega[start:], imu.b_f[start:])
        est.finish()
    kinds = [str(w.message) for w in caught if issubclass(w.category, MessageDropped)]
    print(f"\ncounters {est.counters}; {len(kinds)} warnings")
    for k in (
        "imu_duplicate",
        "imu_out_of_order",
        "imu_not_finite",
        "dvl_duplicate",
        "dvl_out_of_order",
    ):
        assert est.counters.get(k, 0) > 0, k
    assert len(kinds) == 5
    assert (
        est.counters["dvl_duplicate"]
        == est.counters["dvl_out_of_order"]
        == len(range(11, len(dvl), 60))
    )
    np.testing.assert_allclose(_final(est), _final(ref), rtol=1e-9, atol=1e-9)


def test_too_short_static_segment_is_a_clear_error() -> None:
    log = cut_log(_short(), 20.0)
    est = OnlineEstimator.for_log(log)
    with pytest.raises(GtsamDvlError, match="online alignment: no static segment"):
        feed_log(est, log)


def test_options_checked() -> None:
    log = _short()
    for bad in ({"mode": "batch"}, {"bad_messages": "ignore"}, {"window_s": 0.0}):
        with pytest.raises(GtsamDvlError):
            OnlineEstimator.for_log(log, options=OnlineConfig(**bad))  # type: ignore[arg-type]


# ----- helpers ------------------------------------------------------------------------------------


def test_misalignment_closed_form_matches_result_module() -> None:
    """online_types.misalignment_deg_and_cov (closed form) against result.misalignment_rpy_and_cov (numerical),
    including a near-identity correction."""
    rng = np.random.default_rng(3)
    for scale in (1e-7, 1.0, 20.0):
        b_R_d0 = so3_exp(rng.normal(size=3))
        b_R_d = rpy_deg_to_matrix(scale * rng.normal(size=3)) @ b_R_d0
        A = rng.normal(size=(3, 3)) * 1e-3
        cov = A @ A.T
        rpy, c = misalignment_deg_and_cov(b_R_d, b_R_d0, cov)
        rpy_ref, c_ref = misalignment_rpy_and_cov(b_R_d, b_R_d0, cov)
        np.testing.assert_allclose(rpy, rpy_ref, atol=1e-12)
        np.testing.assert_allclose(c, c_ref, rtol=1e-6, atol=1e-12)
