"""The water current per depth layer ([current] layer_thickness_m > 0, estimators/models/current.py "Layers"): the layer
geometry, the crossing links against their formula and numerical derivatives, the EKF's crossing as the exact
linear map, and the three estimators on a log whose descent is tracked on the water in a sheared current."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import S, W
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import DepthData, LogData
from gtsam_dvl.estimators.ekf.strapdown import FilterState, NavState
from gtsam_dvl.estimators.models import current
from tests.support.water import with_water_track

C0 = np.array([0.25, -0.15])  # m/s, east, north: the current at the surface
SHEAR = np.array([-0.008, 0.006])  # m/s per m of depth
T_WATER = (175.0, 300.0)  # s: the descent from the surface to 22 m (paper-3d-short, seed 11)
H = 2.0  # m: the layer thickness of the tests


def _cfg(h: float = H, water_track: str = "use", **more: float) -> EstimatorConfig:
    cfg = EstimatorConfig()
    return cfg.model_copy(
        update={
            "current": cfg.current.model_copy(
                update={"water_track": water_track, "layer_thickness_m": h, **more}
            )
        }
    )


def test_layer_geometry() -> None:
    cfg = _cfg(5.0)
    # depth = -(z + h0): heights above a map origin at -10 m (ellipsoidal), i.e. 10 m under the surface
    assert current.layer_index(cfg, np.array([12.0, 0.0, -4.9, -5.0, -30.0]), -10.0).tolist() == [
        0,
        2,
        2,
        3,
        8,
    ]
    assert current.crossings(2, 2) == []
    assert current.crossings(2, 4) == [(2, 1.0), (3, 1.0)]  # boundary b between layers b and b + 1
    assert current.crossings(4, 1) == [(3, -1.0), (2, -1.0), (1, -1.0)]
    assert current.boundaries(cfg, np.array([-1.0, -12.0, -3.0]), 0.0) == [0, 1]
    assert current.boundaries(_cfg(0.0), np.array([-1.0, -12.0]), 0.0) == []


@pytest.mark.parametrize(("j_from", "j_to"), [(3, 3), (3, 4), (4, 3), (1, 4)])
def test_crossing_link_against_its_formula(j_from: int, j_to: int) -> None:
    """W_j - W_i - sum_b s_b S(b), whitened by q_t sqrt(dt), at random values; its Jacobians against central
    differences (a linear factor on 2 to 5 keys: the JacobianFactor's and the CustomFactor's forms)."""
    cfg = _cfg()
    dt = 4.0
    f = current.crossing_link(cfg, 7, 8, dt, j_from, j_to)
    rng = np.random.default_rng(3)
    values = gtsam.Values()
    for k in (W(7), W(8), *(S(b) for b in range(6))):
        values.insert(k, rng.normal(0.0, 0.3, 2))
    steps = sum(
        (sign * values.atVector(S(b)) for b, sign in current.crossings(j_from, j_to)), np.zeros(2)
    )
    r = (values.atVector(W(8)) - values.atVector(W(7)) - steps) / (
        cfg.current.time_rw_m_s_per_sqrt_s * np.sqrt(dt)
    )
    assert len(f.keys()) == 2 + abs(j_to - j_from)
    assert f.error(values) == pytest.approx(0.5 * r @ r, rel=1e-9)
    jf = gtsam.JacobianFactor(f.linearize(values))
    A, _ = jf.jacobian()
    col = 0
    for k in jf.keys():  # (a linear factor: its whitened residual's Jacobian is its A)
        for c in range(2):
            plus, minus = gtsam.Values(values), gtsam.Values(values)
            e = np.zeros(2)
            e[c] = 1e-6
            plus.update(k, values.atVector(k) + e)
            minus.update(k, values.atVector(k) - e)
            num = (np.sqrt(2 * f.error(plus)) - np.sqrt(2 * f.error(minus))) / 2e-6
            # the norm's derivative along the residual: project A's column the same way
            assert abs(num - (r / np.linalg.norm(r)) @ A[:, col + c]) < 1e-6 * max(1.0, abs(num))
        col += 2


def test_ekf_crossing_is_the_linear_map() -> None:
    """Descending across two boundaries: each enters with its prior q_z^2 h, independent; the current becomes
    W + S(b0) + S(b1) with the covariance T P T^T; climbing back subtracts the same boundaries (no new ones)."""
    cfg = _cfg(5.0)
    rng = np.random.default_rng(4)
    a = rng.normal(size=(23, 23))
    # 19 navigation/calibration components, the correlated error (3) absent, W (2) last: 21
    P0 = a @ a.T * 1e-4
    P0 = P0[:21, :21]
    fs = FilterState(
        NavState(np.eye(3), np.zeros(3), np.array([0.0, 0.0, -1.0])),
        np.zeros(3),
        np.zeros(3),
        1.0,
        np.eye(3),
        P0.copy(),
        current=np.array([0.1, 0.2]),
    )
    current.ekf_start(cfg, fs, 0.0)
    assert fs.layer == 0 and fs.shear is not None and len(fs.shear) == 0
    fs.shear_ids = []
    # layer 2: boundaries 0 and 1
    fs.nav = NavState(np.eye(3), np.zeros(3), np.array([0.0, 0.0, -12.0]))
    current.ekf_propagate(cfg, fs, 0.0, 0.0)  # (dt = 0: the crossing alone)
    q = cfg.current.depth_rw_m_s_per_sqrt_m**2 * 5.0
    Pa = np.zeros((25, 25))  # [nav 19, S0, S1, W] before the crossing, by hand
    Pa[:19, :19], Pa[:19, 23:], Pa[23:, :19], Pa[23:, 23:] = (
        P0[:19, :19],
        P0[:19, 19:],
        P0[19:, :19],
        P0[19:, 19:],
    )
    Pa[19:21, 19:21] = Pa[21:23, 21:23] = q * np.eye(2)
    T = np.eye(25)
    T[23:, 19:21] = T[23:, 21:23] = np.eye(2)
    assert fs.shear_ids == [0, 1] and fs.layer == 2
    np.testing.assert_allclose(fs.P, T @ Pa @ T.T, atol=1e-15)
    fs.shear = np.array([[0.01, 0.02], [0.03, -0.01]])
    before = fs.current.copy() if fs.current is not None else None
    # back to layer 1: boundary 1 upwards
    fs.nav = NavState(np.eye(3), np.zeros(3), np.array([0.0, 0.0, -6.0]))
    current.ekf_propagate(cfg, fs, 0.0, 0.0)
    assert fs.shear_ids == [0, 1] and fs.layer == 1
    assert fs.current is not None and before is not None
    np.testing.assert_allclose(fs.current, before - fs.shear[1])


def sheared_water_track(log: LogData) -> LogData:
    """The log with its pings in T_WATER turned into water-track pings in the current c0 + SHEAR * depth (the true
    depth at each ping; test_water_current.with_water_track: an independent evaluation of the model)."""
    truth = log.truth
    assert truth is not None
    log = with_water_track(
        log, T_WATER, lambda k: np.array([*(C0 + SHEAR * -truth.n_p[k, 2]), 0.0])
    )
    # and a depth sensor at 2 Hz (1 cm): what places the states in their layers (LogGraph.layer_heights)
    t_d = np.arange(truth.t[0], truth.t[-1], 0.5)
    depth_m = -np.interp(t_d, truth.t, truth.n_p[:, 2]) - float(log.metadata["origin"]["height_m"])
    depth_m = depth_m + np.random.default_rng(5).normal(0.0, 0.01, len(t_d))
    return dataclasses.replace(log, depth=DepthData(t_d, depth_m, np.full(len(t_d), 1e-4)))


def true_depth(t: np.ndarray, log: LogData) -> np.ndarray:
    """The true depth below the surface (m) at stamps t."""
    assert log.truth is not None
    return -np.interp(t, log.truth.t, log.truth.n_p[:, 2]) - float(
        log.metadata["origin"]["height_m"]
    )


def true_current(t: np.ndarray, log: LogData) -> np.ndarray:
    truth = log.truth
    assert truth is not None
    depth = -np.interp(t, truth.t, truth.n_p[:, 2])  # (the shear from the map origin's depth down)
    return C0[None, :] + SHEAR[None, :] * depth[:, None]


@pytest.fixture(scope="module")
def layered_log(sim_paper3d_short: LogData) -> LogData:
    """The log to 30 s after the water-track stretch (the descent's pings on bottom track before and after it)."""
    from tests.support.logs import cut_log

    return cut_log(sheared_water_track(sim_paper3d_short), T_WATER[1] + 30.0)


def _log_config(log: LogData, h: float = H) -> EstimatorConfig:
    cfg = EstimatorConfig.for_log(log.metadata)
    return cfg.model_copy(
        update={
            "current": cfg.current.model_copy(
                update={"water_track": "use", "water_track_sigma_m_s": 0.02, "layer_thickness_m": h}
            )
        }
    )


def _assert_current(
    res: NavResult, log: LogData, t_from: float, t_to: float, max_sigma: float
) -> None:
    """The current in [t_from, t_to] within 3 sigma of the truth at every state there (sigmas below max_sigma),
    the scale within 3 sigma."""
    assert res.water_current is not None
    wc = res.water_current.as_dict()
    t = np.asarray(wc["t_s"])
    inside = (t > t_from) & (t < t_to)
    assert inside.sum() > 10
    est = np.stack([wc["east_m_s"], wc["north_m_s"]], axis=1)[inside]
    sig = np.stack([wc["east_sigma_m_s"], wc["north_sigma_m_s"]], axis=1)[inside]
    z = (est - true_current(t[inside], log)) / sig
    assert sig.max() < max_sigma, sig.max()
    assert np.abs(z).max() < 3.0, np.abs(z).max()
    truth = log.true_calibration
    assert truth is not None
    scale = res.calibration["scale"]
    assert abs(scale.value[0] - truth.scale) < 3 * scale.sigma[0]


@pytest.mark.slow
def test_batch_follows_the_sheared_current_per_layer(layered_log: LogData) -> None:
    """Batch with 2 m layers: one boundary variable per boundary crossed (the descent to 22 m: 11), the current at
    every state of the descent within 3 sigma of the truth; the filtering timeline carries the boundaries too (its
    last scale sigma is the smoother's)."""
    from gtsam_dvl.estimators.batch.smoother import smooth_batch

    res = smooth_batch(layered_log, _log_config(layered_log), timeline=True)
    assert res.timeline is not None
    # (rel 1e-5: the smoother's marginals come from its last iteration's linearisation, the timeline's from the
    # solution's)
    assert res.timeline.scale_sigma[-1] == pytest.approx(
        res.calibration["scale"].sigma[0], rel=1e-5
    )
    layers = np.floor(true_depth(res.t, layered_log) / H).astype(int)
    assert res.water_current is not None
    assert res.water_current.layer_boundaries == list(range(layers.min(), layers.max()))
    _assert_current(res, layered_log, T_WATER[0] + 5.0, T_WATER[1] - 5.0, 0.03)
    # each boundary's change: the truth's SHEAR * H (a linear profile: the difference of the layers' means)
    shear = res.water_current.layer_shear
    assert len(shear) == layers.max() - layers.min()
    for s in shear:
        for k, axis in enumerate(("east", "north")):
            assert abs(s[f"{axis}_m_s"] - SHEAR[k] * H) < 3 * s[f"{axis}_sigma_m_s"], s
    headline = summary(res, layered_log)["water_current"]["layers"]
    assert headline["thickness_m"] == H and headline["boundaries"] == len(shear)


@pytest.mark.slow
def test_filters_follow_the_sheared_current_per_layer(layered_log: LogData) -> None:
    """The EKF (a state per boundary crossed, added as it is met) and the online estimator (a variable per
    boundary with the shared states): the current over the last 60 s of the descent within 3 sigma."""
    from gtsam_dvl.estimators.ekf import run_ekf
    from gtsam_dvl.estimators.online import smooth_online

    cfg = _log_config(layered_log)
    ekf = run_ekf(layered_log, cfg)
    layers = np.floor(true_depth(ekf.t, layered_log) / H).astype(int)
    assert ekf.info["filter"]["error_state"] == 19 + 2 + 2 * (layers.max() - layers.min())
    _assert_current(ekf, layered_log, T_WATER[1] - 60.0, T_WATER[1] - 1.0, 0.05)
    online = smooth_online(layered_log, cfg)
    _assert_current(online, layered_log, T_WATER[1] - 60.0, T_WATER[1] - 1.0, 0.05)
