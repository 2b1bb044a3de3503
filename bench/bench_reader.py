"""Reader benchmark: our bulk MCAP reader against the stock mcap_ros2 decoder on the same log.

    .venv/bin/python bench/bench_reader.py [--log LOG.mcap] [--stock-limit N]

Without --log it writes a 2060 s log (206,000 IMU messages at 100 Hz, 1 Hz DVL, 10 Hz truth): from the
simulator's "paper-3d" scenario when that is importable, else from synthetic arrays. Prints IMU
messages per second for both readers, measured in this run, and their ratio.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from gtsam_dvl.core.types import BeamData, DvlData, ImuData, LogData, TruthData
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log


def synthetic_log(duration: float = 2060.0, seed: int = 0) -> LogData:
    """Random but realistic arrays: 100 Hz IMU, 1 Hz DVL with 4 beams, 10 Hz truth."""
    rng = np.random.default_rng(seed)
    n, m, k = int(duration * 100), int(duration), int(duration * 10)
    t = np.arange(1, n + 1) / 100.0
    imu = ImuData(t, rng.normal(0, 1e-3, (n, 3)), rng.normal([0, 0, 9.79], 1e-3, (n, 3)))
    d_v = rng.normal([2.0, 0, 0], 0.02, (m, 3))
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    d_u = np.broadcast_to([[s, 0, c], [-s, 0, c], [0, s, c], [0, -s, c]], (m, 4, 3)).copy()
    beams = BeamData(
        d_u, np.einsum("kij,kj->ki", d_u, d_v), rng.uniform(10, 30, (m, 4)), np.ones((m, 4), bool)
    )
    dvl = DvlData(
        np.arange(1, m + 1, dtype=float),
        d_v,
        np.tile(4e-4 * np.eye(3), (m, 1, 1)),
        np.ones(m, bool),
        beams,
    )
    q = np.tile([0.0, 0.0, 0.0, 1.0], (k, 1))
    truth = TruthData(
        np.arange(k) / 10.0,
        rng.normal(0, 100, (k, 3)),
        q,
        rng.normal(0, 2, (k, 3)),
        np.zeros((k, 3)),
    )
    return LogData(
        imu,
        dvl,
        truth=truth,
        t0_ns=1_700_000_000 * 10**9,
        metadata={"generator": "bench synthetic"},
    )


def make_log(path: Path) -> tuple[str, float]:
    """Write the benchmark log; returns where its arrays came from and the write_log time (s)."""
    try:
        from gtsam_dvl.sim import simulate
        from gtsam_dvl.sim.scenario import load_scenario

        log = simulate(load_scenario("paper-3d"), 7)
        origin = "simulator, scenario paper-3d, seed 7"
    except Exception as e:  # simulator not there (or its API differs): synthetic arrays
        log, origin = (
            synthetic_log(),
            f"synthetic arrays (simulator unavailable: {type(e).__name__}: {e})",
        )
    t = time.perf_counter()
    write_log(path, log)
    return origin, time.perf_counter() - t


def bench_ours(path: Path, repeat: int) -> tuple[float, int]:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        log = read_log(path)
        best = min(best, time.perf_counter() - t)
    return best, len(log.imu)


def bench_stock(path: Path, limit: int | None) -> tuple[float, int]:
    """The stock path: mcap's reader with mcap_ros2's decoder factory, IMU topic only, into the same
    numpy arrays."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    t = time.perf_counter()
    stamps, omega, force = [], [], []
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for i, (_, _, _, m) in enumerate(reader.iter_decoded_messages(topics=["/imu/data_raw"])):
            stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)
            omega.append((m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z))
            force.append(
                (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z)
            )
            if limit is not None and i + 1 >= limit:
                break
    np.array(stamps), np.array(omega), np.array(force)
    return time.perf_counter() - t, len(stamps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, help="an existing log (.mcap) instead of a generated one")
    ap.add_argument("--repeat", type=int, default=3, help="runs of our reader (best is kept)")
    ap.add_argument(
        "--stock-limit", type=int, default=None, help="stop the stock reader after N messages"
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.log
        if path is None:
            path = Path(tmp) / "bench.mcap"
            origin, write_s = make_log(path)
            print(f"log: {origin}")
            print(f"write_log: {write_s:.2f} s ({path.stat().st_size / 1e6:.1f} MB)")
        ours_s, n_ours = bench_ours(path, args.repeat)
        stock_s, n_stock = bench_stock(path, args.stock_limit)
    ours, stock = n_ours / ours_s, n_stock / stock_s
    print(f"{'reader':<46} {'IMU msgs':>9} {'seconds':>8} {'IMU msgs/s':>11}")
    print(
        f"{'gtsam_dvl read_log (all topics, to LogData)':<46} {n_ours:>9} {ours_s:>8.3f} {ours:>11,.0f}"
    )
    print(
        f"{'mcap + mcap_ros2 DecoderFactory (IMU only)':<46} {n_stock:>9} {stock_s:>8.3f} {stock:>11,.0f}"
    )
    print(f"ratio ours/stock: {ours / stock:.1f}x")


if __name__ == "__main__":
    main()
