"""The simulator's sensor errors beyond white noise: the IMU's per-axis quantisation (the logged samples are
multiples of the step; the rounding error is white, q / sqrt(12), while the vehicle oscillates, and is not while it
holds a constant rate), the DVL's first-order Gauss-Markov velocity error (its stationary std and autocorrelation),
the [oscillation] motion (the IMU integrates to the truth through it and through an arc), and the random streams
of the scenarios without these errors (unchanged)."""

from __future__ import annotations

import copy
import re
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.dvl import GaussMarkov, correlated_error
from gtsam_dvl.sim.imu import quantise
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from gtsam_dvl.sim.stream import simulate_chunked
from tests.support.scenarios import scenario_raw
from tests.support.strapdown import _check_window

Q_GYRO = (1e-4, 2e-4, 5e-5)  # rad/s, a different step per axis
Q_ACCEL = 1e-4  # m/s^2, one step for all three


def _raw(duration_s: float = 200.0, **tables: Any) -> dict[str, Any]:
    """straight-transect (oscillating, quantised, correlated DVL error) shortened to duration_s, tables updated."""
    raw = scenario_raw(
        "straight-transect", segments=[{"kind": "straight", "duration_s": duration_s}]
    )
    raw["imu"].update(quantisation_gyro_rad_s=list(Q_GYRO), quantisation_accel_m_s2=Q_ACCEL)
    for key, value in tables.items():
        if value is None:
            raw.pop(key, None)
        else:
            raw[key] = {**raw.get(key, {}), **value}
    return raw


def _sim(raw: dict[str, Any], seed: int = 4, white_noise: bool = True) -> LogData:
    return simulate(
        scenario_from_dict(copy.deepcopy(raw), name="errors"), seed, white_noise=white_noise
    )


def _unquantised(raw: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(raw)
    out["imu"].update(quantisation_gyro_rad_s=0.0, quantisation_accel_m_s2=0.0)
    return out


def _lag_corr(x: np.ndarray, lag: int) -> np.ndarray:
    """Sample autocorrelation per column at a lag."""
    x = x - x.mean(axis=0)
    return (x[lag:] * x[:-lag]).sum(axis=0) / (x * x).sum(axis=0)


# ----- quantisation -----------------------------------------------------------------------------------------------
def test_logged_imu_samples_are_multiples_of_the_step_of_each_axis() -> None:
    log = _sim(_raw(60.0))
    for x, q in ((log.imu.b_omega, np.array(Q_GYRO)), (log.imu.b_f, np.full(3, Q_ACCEL))):
        steps = x / q
        off = np.abs(steps - np.round(steps)).max(axis=0)
        print(
            f"steps {q}: largest distance from a multiple {off} steps; distinct values per axis "
            f"{[len(np.unique(x[:, i])) for i in range(3)]}"
        )
        assert np.all(off < 1e-6)
        # the outputs move across many steps
        assert all(len(np.unique(x[:, i])) > 20 for i in range(3))
    raw = _raw(60.0)
    raw["imu"]["quantisation_accel_m_s2"] = [Q_ACCEL, 0.0, Q_ACCEL]  # 0: that axis is not quantised
    y = _sim(raw).imu.b_f[:, 1]
    assert np.abs(y / Q_ACCEL - np.round(y / Q_ACCEL)).max() > 0.1


def test_quantise_rounds_to_the_nearest_multiple() -> None:
    x = np.array([[0.24e-4, -0.56e-4, 1.0], [1.49e-4, 2.51e-4, -3.0]])
    np.testing.assert_allclose(
        quantise(x, (1e-4, 1e-4, 0.0)), [[0.0, -1e-4, 1.0], [1e-4, 3e-4, -3.0]], atol=1e-18
    )
    assert quantise(x, 0.0) is x


def _mean_rms_ratio(err: np.ndarray, q: np.ndarray, n: int = 100) -> np.ndarray:
    """RMS of the n-sample means of err per column (its mean included), over the white value (q / sqrt(12)) / sqrt(n):
    1 for a white rounding error, far above 1 for one that stays the same."""
    means = err[: len(err) // n * n].reshape(-1, n, err.shape[1]).mean(axis=1)
    return np.sqrt((means**2).mean(axis=0)) / (q / np.sqrt(12.0) / np.sqrt(n))


def test_rounding_error_is_white_while_oscillating_and_not_at_a_constant_rate() -> None:
    """The rounding error (the log minus the same seed's unquantised log) has std q / sqrt(12) per axis within
    5 %, nearly no correlation from one sample to the next and 1 s means at the white level, while the vehicle
    oscillates and vibrates (straight-transect's [oscillation]); its slow motions alone leave the error correlated
    from sample to sample; without any oscillation the gyro outputs hold still and the error stays a fraction of a step:
    a gyro bias of several deg/h, not white noise."""
    raw = _raw(200.0)
    q = np.concatenate([Q_GYRO, np.full(3, Q_ACCEL)])
    a, b = _sim(raw), _sim(_unquantised(raw))
    err = np.hstack([a.imu.b_omega - b.imu.b_omega, a.imu.b_f - b.imu.b_f])
    ratio = err.std(axis=0) / (q / np.sqrt(12.0))
    lag1 = _lag_corr(err, 1)
    mean_ratio = _mean_rms_ratio(err, q)
    print(
        f"oscillating: std / (q/sqrt(12)) gyro {np.round(ratio[:3], 3)} accel {np.round(ratio[3:], 3)}; lag-1 "
        f"correlation {np.round(lag1, 3)}; 1 s means / white {np.round(mean_ratio, 2)}"
    )
    assert np.all(np.abs(ratio - 1.0) < 0.05)
    assert np.all(np.abs(lag1) < 0.15)
    assert np.all((mean_ratio > 0.7) & (mean_ratio < 1.3))  # 200 means: +-5 % sampling (1 sigma)

    # the slow motions without the vibration: pitch and yaw rates move 0.1-0.2 steps a sample
    slow = _raw(200.0)
    for key in (
        "roll_deg",
        "roll_period_s",
        "pitch_deg",
        "pitch_period_s",
        "yaw_deg",
        "yaw_period_s",
    ):
        slow["oscillation"][key] = slow["oscillation"][key][0]
    e, f = _sim(slow), _sim(_unquantised(slow))
    lag1_slow = _lag_corr(e.imu.b_omega - f.imu.b_omega, 1)
    print(f"slow motions only: gyro rounding error lag-1 correlation {np.round(lag1_slow, 3)}")
    assert np.max(lag1_slow) > 0.3

    still = _raw(200.0, oscillation=None)
    c, d = _sim(still), _sim(_unquantised(still))
    err_still = c.imu.b_omega - d.imu.b_omega
    mean_still = _mean_rms_ratio(err_still, np.array(Q_GYRO))
    print(
        f"constant rate: gyro rounding error mean {np.round(err_still.mean(axis=0) / np.array(Q_GYRO), 2)} steps "
        f"({np.round(err_still.mean(axis=0) / DEG_PER_H, 1)} deg/h), 1 s means / white {np.round(mean_still, 1)}"
    )
    assert np.sum(mean_still > 3.0) >= 2  # the error does not average out


# ----- the DVL's Gauss-Markov error -------------------------------------------------------------------------------
def test_gauss_markov_std_and_autocorrelation_over_a_long_series() -> None:
    sigma, tau, dt, n = 0.002, 20.0, 1.0, 200_000
    x = GaussMarkov(sigma, tau, dt, np.random.default_rng(3)).take(n)
    lag = int(tau / dt)
    rho = _lag_corr(x, lag)
    print(
        f"std {x.std(axis=0) * 1e3} mm/s (sigma {sigma * 1e3}); correlation at lag tau {np.round(rho, 4)} "
        f"(exp(-1) = {np.exp(-1):.4f}); at 5 tau {np.round(_lag_corr(x, 5 * lag), 4)}"
    )
    assert np.all(np.abs(x.std(axis=0) / sigma - 1.0) < 0.10)
    assert np.all(np.abs(rho - np.exp(-1.0)) < 0.03)  # the estimate's sampling sigma is 0.008
    assert np.all(np.abs(_lag_corr(x, 5 * lag)) < 0.05)  # exp(-5) = 0.007


def test_gauss_markov_starts_stationary_and_continues_across_calls() -> None:
    sigma = 0.002
    first = np.array(
        [GaussMarkov(sigma, 60.0, 1.0, np.random.default_rng(s)).take(1)[0] for s in range(3000)]
    )
    print(f"first-ping std over 3000 runs {first.std(axis=0) * 1e3} mm/s")
    # 9000 draws: 0.75 % sampling sigma
    assert np.all(np.abs(first.std(axis=0) / sigma - 1.0) < 0.05)
    whole = GaussMarkov(sigma, 60.0, 1.0, np.random.default_rng(9)).take(50)
    gm = GaussMarkov(sigma, 60.0, 1.0, np.random.default_rng(9))
    parts = np.vstack([gm.take(1), gm.take(0), gm.take(20), gm.take(29)])
    assert np.array_equal(parts, whole)


def test_correlated_error_is_its_own_stream_and_only_moves_the_dvl_velocity() -> None:
    """Switched on, the correlated error is the difference of the DVL velocities and nothing else changes (the IMU,
    the truth, the beams' validity); its draws come from SeedSequence(seed)'s seventh child."""
    raw = _raw(120.0)
    off = copy.deepcopy(raw)
    off["dvl"]["correlated_sigma_m_s"] = 0.0
    on_log, off_log = _sim(raw, seed=8), _sim(off, seed=8)
    sc = scenario_from_dict(copy.deepcopy(raw))
    gm = correlated_error(sc.dvl, sc.rates.dvl_hz, 8)
    assert gm is not None
    np.testing.assert_allclose(
        on_log.dvl.d_v - off_log.dvl.d_v, gm.take(len(on_log.dvl)), rtol=0, atol=1e-15
    )
    for name in ("b_omega", "b_f"):
        assert np.array_equal(getattr(on_log.imu, name), getattr(off_log.imu, name))
    assert on_log.truth is not None and off_log.truth is not None
    assert np.array_equal(on_log.truth.n_p, off_log.truth.n_p)
    assert np.array_equal(on_log.dvl.valid, off_log.dvl.valid)
    assert on_log.metadata["sensors"]["dvl"]["correlated_sigma_m_s"] == 0.002
    # off: the metadata of before
    assert "correlated_sigma_m_s" not in off_log.metadata["sensors"]["dvl"]
    clean = _sim(raw, seed=8, white_noise=False)  # white_noise=False: no random error at all
    assert clean.truth is not None
    # the truth's speed
    np.testing.assert_allclose(np.linalg.norm(clean.dvl.d_v, axis=1), 1.9, atol=0.03)


@pytest.mark.parametrize("name", ["paper-3d-short", "field-survey"])
def test_scenarios_without_the_new_errors_keep_their_numbers(name: str) -> None:
    """A scenario that sets the new keys to their off values simulates to the same log, bit for bit (the streams
    of the scenarios without them are those they always had)."""
    raw = copy.deepcopy(load_scenario(name).raw)
    base = simulate(scenario_from_dict(copy.deepcopy(raw), name=name), 5)
    raw["imu"].update(quantisation_gyro_rad_s=0.0, quantisation_accel_m_s2=[0.0, 0.0, 0.0])
    raw["dvl"].update(correlated_sigma_m_s=0.0, correlated_tau_s=30.0)
    again = simulate(scenario_from_dict(raw, name=name), 5)
    for part in ("imu", "dvl", "truth"):
        for f in ("t", "b_omega", "b_f", "d_v", "n_p", "n_q_b"):
            if hasattr(getattr(base, part), f):
                assert np.array_equal(
                    getattr(getattr(base, part), f),
                    getattr(getattr(again, part), f),
                    equal_nan=True,
                ), (part, f)
    assert base.metadata["sensors"] == again.metadata["sensors"]


def test_chunked_simulation_matches_with_the_new_errors() -> None:
    """sim/stream.py continues the quantisation, the Gauss-Markov error, the oscillation and an arc chunk by chunk:
    its log is simulate()'s bit for bit, with chunks of one ping."""
    raw = _raw(30.0)
    raw["segments"] = [
        {"kind": "arc", "duration_s": 15.0, "turn_rate_deg_s": 2.0},
        {"kind": "straight", "duration_s": 15.0},
    ]
    sc = scenario_from_dict(raw, name="errors")
    ref = simulate(sc, 2)
    for chunk_s in (0.7, 11.0):
        part = simulate_chunked(sc, 2, chunk_s=chunk_s)
        for name in ("b_omega", "b_f"):
            assert np.array_equal(getattr(part.imu, name), getattr(ref.imu, name)), (chunk_s, name)
        assert np.array_equal(part.dvl.d_v, ref.dvl.d_v, equal_nan=True), chunk_s
        assert part.truth is not None and ref.truth is not None
        assert np.array_equal(part.truth.n_q_b, ref.truth.n_q_b), chunk_s


# ----- oscillation and arc: one trajectory for the truth and the sensors ---------------------------------------
@pytest.mark.parametrize(
    ("label", "t_start"), [("oscillating arc", 5.0), ("arc end to straight", 30.0)]
)
def test_strapdown_reproduces_the_truth_through_oscillation_and_arcs(
    label: str, t_start: float
) -> None:
    """An independent strapdown integration of the noise-free, unquantised IMU follows the truth through the
    oscillation, a steady turn and its end (the turn rate steps at an IMU stamp): the truth includes the motion
    the IMU measures (test_sim_physics.py's bounds: 1 % of the white-noise drift)."""
    raw = _unquantised(_raw())
    raw["segments"] = [
        {"kind": "arc", "duration_s": 60.0, "turn_rate_deg_s": 0.57},
        {"kind": "straight", "duration_s": 40.0},
    ]
    sc = scenario_from_dict(raw, name="osc-arc")
    log = simulate(sc, 1, white_noise=False)
    _check_window(log, sc.local_frame(), label, t_start, T=45.0)


def test_bad_error_and_oscillation_keys_are_one_line_errors() -> None:
    for table, key, value, text in (
        ("imu", "quantisation_gyro_rad_s", -1e-4, "must be >= 0"),
        ("imu", "quantisation_accel_m_s2", [1e-4, 1e-4], "list of 3 numbers"),
        ("dvl", "correlated_sigma_m_s", -0.001, "must be >= 0"),
        ("dvl", "correlated_tau_s", 0.0, "must be positive"),
        ("oscillation", "roll_period_s", [7.0, 0.01], "at least 4 IMU samples (0.04 s)"),
        ("oscillation", "pitch_period_s", 11.0, "one period per amplitude (2)"),
        ("oscillation", "heave_m", [], "a number or a list of numbers"),
        ("oscillation", "yaw_deg", [20.0, 0.0], "within +-10 deg"),
        ("oscillation", "sway_m", 1.0, "unknown key"),
    ):
        raw = _raw(10.0)
        raw[table][key] = value
        with pytest.raises(
            GtsamDvlError, match=re.escape(f"key '{table}.{key}'") + ".*" + re.escape(text)
        ) as exc:
            scenario_from_dict(raw, source="x.toml")
        assert "\n" not in str(exc.value)


def test_dvl_preset_fills_what_the_scenario_does_not_set() -> None:
    """[dvl] model = a DVL preset: its ping noise, correlated error, bottom-track range and beam angle, unless the
    table sets them; the truth scale stays the table's; an unknown name is one line naming the known ones."""
    from gtsam_dvl.core.config.presets import DVL_PRESETS
    from gtsam_dvl.core.errors import GtsamDvlError
    from gtsam_dvl.sim.scenario import scenario_from_dict
    from tests.support.scenarios import scenario_raw

    p = DVL_PRESETS["teledyne-pathfinder"]
    raw = scenario_raw(dvl={"model": "teledyne-pathfinder", "scale": 1.003})
    for key in ("noise_m_s", "correlated_sigma_m_s", "max_range_m"):
        raw["dvl"].pop(key, None)
    spec = scenario_from_dict(raw).dvl
    assert spec.noise_m_s == p.ping_noise_m_s and spec.max_range_m == p.max_altitude_m
    assert spec.correlated_sigma_m_s == p.correlated_sigma_m_s > 0 and spec.scale == 1.003
    explicit = scenario_from_dict(
        scenario_raw(dvl={"model": "teledyne-pathfinder", "noise_m_s": 0.004})
    ).dvl
    assert explicit.noise_m_s == 0.004
    with pytest.raises(
        GtsamDvlError, match="'nortek-x' is not one of .*teledyne-pathfinder"
    ) as err:
        scenario_from_dict(scenario_raw(dvl={"model": "nortek-x"}))
    assert "\n" not in str(err.value)
