"""Cost of linearising the DVL CustomFactors (Python callbacks) against a C++ factor, in one run.

Prints microseconds per factor for graph.linearize(values) over N factors, best of several repeats, and the
ratio to GTSAM's C++ BetweenFactorPose3 measured in the same run.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, K, V, X

from gtsam_dvl.factors import make_dvl_beam_factor, make_dvl_velocity_factor

N = 2000
REPEATS = 7


def best_of(fn) -> float:
    fn()  # warm-up
    best = float("inf")
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best / N * 1e6


def main() -> None:
    rng = np.random.default_rng(0)
    values = gtsam.Values()
    values.insert(K(0), np.array([0.9998]))
    values.insert(B(0), gtsam.Rot3.Rx(np.pi))
    for i in range(N + 1):
        values.insert(X(i), gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3)), rng.normal(size=3)))
        values.insert(V(i), rng.normal(size=3))
    b_omega, b_l = np.array([0.01, -0.02, 0.05]), np.array([0.6, -0.1, -0.4])
    d_u = np.array([0.5, 0.0, np.sqrt(0.75)])

    names = ("dvl_velocity", "dvl_beam", "BetweenFactorPose3")
    graphs = {name: gtsam.NonlinearFactorGraph() for name in names}
    noise3, noise1 = (
        gtsam.noiseModel.Isotropic.Sigma(3, 0.02),
        gtsam.noiseModel.Isotropic.Sigma(1, 0.02),
    )
    noise6 = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)
    for i in range(N):
        keys = (X(i), V(i), K(0), B(0))
        graphs["dvl_velocity"].add(
            make_dvl_velocity_factor(noise3, *keys, rng.normal(size=3), b_omega, b_l)
        )
        graphs["dvl_beam"].add(make_dvl_beam_factor(noise1, *keys, d_u, rng.normal(), b_omega, b_l))
        graphs["BetweenFactorPose3"].add(
            gtsam.BetweenFactorPose3(X(i), X(i + 1), gtsam.Pose3(), noise6)
        )

    lin = {name: best_of(lambda g=g: g.linearize(values)) for name, g in graphs.items()}
    err = {name: best_of(lambda g=g: g.error(values)) for name, g in graphs.items()}
    ref = lin["BetweenFactorPose3"]
    print(f"{N} factors, best of {REPEATS}")
    print(f"{'factor':22s} {'linearize us':>13s} {'ratio to C++':>13s} {'error us':>9s}")
    for name in graphs:
        print(f"{name:22s} {lin[name]:13.1f} {lin[name] / ref:13.1f} {err[name]:9.1f}")


if __name__ == "__main__":
    main()
