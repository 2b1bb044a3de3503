"""The registry of the shared states (core/states.py): each entry's key, dimension and units, its prior from the
configuration, its enabling, and that the elimination ordering, the iSAM2 window, the timeline's and the EKF's
layouts list exactly the enabled states."""

from __future__ import annotations

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core import states
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, K_WATER, L_LEVER, T_OFFSET, B, E, V, X, key_dim
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.ekf import strapdown
from gtsam_dvl.estimators.ekf.model import initial_state
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.inputs.alignment import Alignment
from gtsam_dvl.estimators.online.window import IncrementalSmoother

EXPECTED = {  # name: key, dimension, unit, display unit, display per unit, vehicle property
    "gyro_bias": (B(0), 3, "rad/s", "deg/h", 1.0 / DEG_PER_H, False),
    "accel_bias": (B(0), 3, "m/s^2", "micro-g", 1.0 / UG, False),
    "scale": (K_SCALE, 1, "1", "ppm", 1e6, True),
    "misalignment": (C_MISALIGN, 3, "rad", "deg", 180.0 / np.pi, True),
    "time_offset": (T_OFFSET, 1, "s", "ms", 1e3, True),
    "lever_arm": (L_LEVER, 3, "m", "m", 1.0, True),
    "water_scale": (K_WATER, 1, "1", "ppm", 1e6, True),
}


def _config(offset: bool, lever: bool, random_walk: bool = False) -> EstimatorConfig:
    cfg = EstimatorConfig.from_dict(
        {
            "imu": {
                "gyro_bias_sigma_deg_per_h": 0.03,
                "accel_bias_sigma_ug": 70.0,
                "bias_model": "random_walk" if random_walk else "constant",
            },
            "priors": {
                "scale_initial": 0.9,
                "scale_sigma": 0.2,
                "misalignment_sigma_deg": [1.0, 2.0, 3.0],
            },
            "dvl": {
                "estimate_time_offset": offset,
                "estimate_lever_arm": lever,
                "time_offset_prior_s": 0.3,
                "time_offset_sigma_s": 0.7,
                "lever_arm_sigma_m": 0.4,
            },
            "observability": {
                "scale_ppm": 500.0,
                "misalignment_deg": 0.2,
                "accel_bias_ug": 11.0,
                "gyro_bias_deg_per_h": 0.002,
            },
        }
    )
    return cfg


MOUNTING = Mounting(
    b_R_d0=rpy_deg_to_matrix([180.0, 0.0, 45.0]), b_p_dvl=np.array([0.5, -0.1, -0.3])
)
CONFIGS = [(o, lv) for o in (False, True) for lv in (False, True)]


def _names(cfg: EstimatorConfig) -> list[str]:
    return [
        n
        for n in EXPECTED
        if n not in ("time_offset", "lever_arm", "water_scale")
        or (n == "time_offset" and cfg.dvl.estimate_time_offset)
        or (n == "lever_arm" and cfg.dvl.estimate_lever_arm)
    ]  # (water_scale: test_water_track_scale_link)


def _keys(cfg: EstimatorConfig) -> list[int]:
    return (
        [B(0), K_SCALE, C_MISALIGN]
        + [T_OFFSET] * cfg.dvl.estimate_time_offset
        + [L_LEVER] * cfg.dvl.estimate_lever_arm
    )


def test_entries_key_dimension_units_scope() -> None:
    assert [s.name for s in states.STATES] == list(EXPECTED)
    for s in states.STATES:
        key, dim, unit, display, factor, vehicle = EXPECTED[s.name]
        assert (s.key, s.dim, s.unit, s.display_unit, s.vehicle) == (
            key,
            dim,
            unit,
            display,
            vehicle,
        ), s.name
        assert s.to_display == pytest.approx(factor, rel=1e-15)
        assert len(s.components) == s.dim
    # the states on a key fill its tangent exactly: the bias key B holds [accel, gyro]
    for key in {s.key for s in states.STATES}:
        on_key = sorted((s for s in states.STATES if s.key == key), key=lambda s: s.offset)
        assert [s.offset for s in on_key] == list(np.cumsum([0] + [s.dim for s in on_key])[:-1])
        assert sum(s.dim for s in on_key) == key_dim(key)
    assert [s.name for s in states.block_states()] == [
        "accel_bias",
        "gyro_bias",
        "scale",
        "misalignment",
    ]
    assert [s.name for s in states.required_states()] == [
        "gyro_bias",
        "accel_bias",
        "scale",
        "misalignment",
    ]


def test_priors_and_targets_from_the_configuration() -> None:
    cfg = _config(True, True)
    p = {s.name: s.prior(cfg, MOUNTING) for s in states.STATES}
    np.testing.assert_array_equal(p["gyro_bias"].cov, np.eye(3) * (0.03 * DEG_PER_H) ** 2)
    np.testing.assert_array_equal(p["accel_bias"].cov, np.eye(3) * (70.0 * UG) ** 2)
    np.testing.assert_array_equal(p["scale"].value, [0.9])
    np.testing.assert_array_equal(p["scale"].cov, [[0.2**2]])
    np.testing.assert_array_equal(p["misalignment"].value, MOUNTING.b_R_d0)
    mis = np.radians([1.0, 2.0, 3.0])
    np.testing.assert_allclose(
        p["misalignment"].cov, MOUNTING.b_R_d0.T @ np.diag(mis**2) @ MOUNTING.b_R_d0
    )
    np.testing.assert_array_equal(p["time_offset"].value, [0.3])
    np.testing.assert_array_equal(p["time_offset"].cov, [[0.7**2]])
    np.testing.assert_array_equal(p["lever_arm"].value, MOUNTING.b_l)
    np.testing.assert_array_equal(p["lever_arm"].cov, np.eye(3) * 0.4**2)
    shown = {s.name: s.prior_display_sigma(cfg).tolist() for s in states.STATES}
    assert shown == {
        "gyro_bias": [0.03] * 3,
        "accel_bias": [70.0] * 3,
        "scale": [0.2e6],
        "misalignment": [1.0, 2.0, 3.0],
        "time_offset": [700.0],
        "lever_arm": [0.4] * 3,
        "water_scale": [1e6],
    }  # its information is the link to the scale (test_water_track_scale_link)
    targets = {s.name: s.target(cfg.observability) for s in states.STATES if s.target is not None}
    assert targets == {"gyro_bias": 0.002, "accel_bias": 11.0, "scale": 500.0, "misalignment": 0.2}


@pytest.mark.parametrize(("offset", "lever"), CONFIGS)
def test_enabled_states_their_keys_priors_and_initial_values(offset: bool, lever: bool) -> None:
    cfg = _config(offset, lever)
    assert [s.name for s in states.enabled_states(cfg)] == _names(cfg)
    assert states.shared_keys(cfg) == _keys(cfg)
    assert states.shared_keys(cfg, block=True) == [B(0), K_SCALE, C_MISALIGN]
    factors = states.prior_factors(cfg, MOUNTING)
    assert [f.keys()[0] for f in factors] == _keys(cfg)
    values = states.initial_values(cfg, MOUNTING)
    assert sorted(values.keys()) == sorted(_keys(cfg))
    for f in factors:  # each prior is centred on the initial value
        assert f.error(values) == pytest.approx(0.0, abs=1e-20)
    est = states.read_estimates(values, {k: np.eye(key_dim(k)) for k in _keys(cfg)}, cfg)
    assert list(est) == _names(cfg)
    np.testing.assert_array_equal(est["misalignment"].value, MOUNTING.b_R_d0)
    np.testing.assert_array_equal(est["scale"].value, [0.9])


def test_priors_are_those_of_the_factor_maker() -> None:
    """The registry's priors, factor by factor, against FactorMaker.prior_factors (the shared states' keys)."""
    cfg = _config(True, True)
    maker = FactorMaker(
        cfg, LocalFrame(45.0, 10.0), Alignment(np.eye(3), 0.0, "configured"), MOUNTING
    )
    values = maker.first_state_values(np.array([1.0, 0.0, 0.0]))
    theirs = {
        f.keys()[0]: f for f in maker.prior_factors(values) if f.keys()[0] not in (X(0), V(0))
    }
    ours = states.prior_factors(cfg, MOUNTING)
    assert [f.keys()[0] for f in ours] == list(theirs)
    for f in ours:
        g = theirs[f.keys()[0]]
        np.testing.assert_array_equal(f.noiseModel().covariance(), g.noiseModel().covariance())
        assert type(f.noiseModel()) is type(g.noiseModel())
        assert f.equals(g, 0.0)
    ours_values = states.read_values(states.initial_values(cfg, MOUNTING), cfg)
    theirs_values = states.read_values(values, cfg)
    for name, value in ours_values.items():
        np.testing.assert_array_equal(value, theirs_values[name])


@pytest.mark.parametrize(
    ("offset", "lever", "random_walk"),
    [(o, lv, False) for o, lv in CONFIGS] + [(True, False, True)],
)
def test_elimination_ordering_lists_the_enabled_states(
    offset: bool, lever: bool, random_walk: bool
) -> None:
    cfg = _config(offset, lever, random_walk)
    # (no per-epoch state's extra variables: no water-current layer boundaries)
    graph = SimpleNamespace(config=cfg, epochs=[None] * 3, extra_keys=[])
    ordering = LogGraph.elimination_ordering(graph, chunk_states=2)  # type: ignore[arg-type]
    shared = _keys(cfg)[1:] if random_walk else _keys(cfg)
    assert ordering.rest == shared
    assert [k for ks in ordering.chunks for k in ks] == [
        k for i in range(3) for k in [X(i), V(i)] + [B(i)] * random_walk + [E(i)]
    ]


@pytest.mark.parametrize(("offset", "random_walk"), [(False, False), (True, False), (True, True)])
def test_window_shares_the_enabled_states(offset: bool, random_walk: bool) -> None:
    cfg = _config(offset, False, random_walk)
    maker = SimpleNamespace(config=cfg, bias_key=lambda i: B(i) if random_walk else B(0))
    smoother = IncrementalSmoother(maker, 10.0, cfg.online.relinearization)  # type: ignore[arg-type]
    assert smoother.shared_keys(4) == [B(4) if random_walk else B(0)] + _keys(cfg)[1:]
    # (e: the DVL's correlated error, modelled by default: estimators/models/correlated.py)
    assert set(smoother._threshold) == {"x", "v", "b", "k", "c", "e"} | ({"t"} if offset else set())
    assert smoother._state_keys(4)[-1] == E(4)


@pytest.mark.parametrize(("offset", "lever"), CONFIGS)
def test_timeline_and_ekf_layouts_list_the_enabled_states(offset: bool, lever: bool) -> None:
    cfg = _config(offset, lever)
    cols = states.columns(states.shared_keys(cfg), cfg, start=9)
    assert list(cols) == _names(cfg)
    assert cols["accel_bias"] == slice(9, 12) and cols["gyro_bias"] == slice(12, 15)
    assert cols["scale"] == slice(15, 16) and cols["misalignment"] == slice(16, 19)
    if lever:
        assert cols["lever_arm"] == slice(19 + offset, 22 + offset)
    # the EKF: every enabled state but the lever arm, in the strapdown's error-state order
    layout = states.ekf_layout(cfg, strapdown.PHI.stop + 6)
    assert list(layout) == [n for n in _names(cfg) if n != "lever_arm"]
    assert (layout["gyro_bias"], layout["accel_bias"]) == (strapdown.BG, strapdown.BA)
    assert (layout["scale"], layout["misalignment"]) == (
        slice(strapdown.SCALE, strapdown.SCALE + 1),
        strapdown.MIS,
    )
    log = SimpleNamespace(mounting=MOUNTING, dvl=SimpleNamespace(d_v=np.array([[1.0, 0.0, 0.0]])))
    fs = initial_state(log, cfg, np.eye(3), 0)  # type: ignore[arg-type]
    assert fs.P.shape == (strapdown.N_ERR + offset + 3,) * 2  # the correlated DVL error last
    assert fs.error_slice() == slice(strapdown.N_ERR + offset, strapdown.N_ERR + offset + 3)
    for name, sl in layout.items():
        np.testing.assert_array_equal(fs.P[sl, sl], states.BY_NAME[name].prior(cfg, MOUNTING).cov)
    assert fs.scale == 0.9 and fs.time_offset == (0.3 if offset else 0.0)


def test_values_read_back_by_state() -> None:
    cfg = _config(True, True)
    values = gtsam.Values()
    values.insert(
        B(0), gtsam.imuBias.ConstantBias(np.array([1.0, 2.0, 3.0]), np.array([4.0, 5.0, 6.0]))
    )
    values.insert(K_SCALE, np.array([1.01]))
    values.insert(C_MISALIGN, gtsam.Rot3(MOUNTING.b_R_d0))
    values.insert(T_OFFSET, np.array([0.25]))
    values.insert(L_LEVER, np.array([0.1, 0.2, 0.3]))
    cov = {k: np.diag(np.arange(1.0, key_dim(k) + 1)) for k in _keys(cfg)}
    est = states.read_estimates(values, cov, cfg)
    np.testing.assert_array_equal(est["accel_bias"].value, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(est["gyro_bias"].value, [4.0, 5.0, 6.0])
    np.testing.assert_array_equal(est["gyro_bias"].cov, np.diag([4.0, 5.0, 6.0]))
    np.testing.assert_array_equal(est["time_offset"].value, [0.25])
    np.testing.assert_array_equal(est["lever_arm"].sigma, np.sqrt([1.0, 2.0, 3.0]))


def test_water_track_scale_link() -> None:
    """[current] water_track_scale: the water-track scale K_WATER a state (only with water-track pings used), its
    prior the scale's and a link k_w - k ~ N(0, (sigma k_0)^2) among the priors: 0.5 ((k_w - k) / (sigma k_0))^2."""
    cfg = EstimatorConfig.from_dict(
        {
            "priors": {"scale_initial": 0.9, "scale_sigma": 0.2},
            "current": {
                "water_track": "use",
                "water_track_scale": True,
                "water_track_scale_sigma": 0.02,
            },
        }
    )
    assert states.enabled(cfg, "water_scale") and not states.enabled(
        EstimatorConfig(), "water_scale"
    )
    factors = states.prior_factors(cfg, MOUNTING)
    links = [f for f in factors if set(f.keys()) == {K_WATER, K_SCALE}]
    assert len(links) == 1
    values = states.initial_values(cfg, MOUNTING)
    values.update(K_WATER, np.array([0.93]))
    values.update(K_SCALE, np.array([0.91]))
    assert links[0].error(values) == pytest.approx(0.5 * (0.02 / (0.02 * 0.9)) ** 2)
