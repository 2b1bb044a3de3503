"""Study: how well does a mission calibrate the DVL misalignment about the thrust axis (roll), as a
function of the descent's duration and the DVL rate?

Covariance analysis with the planning API (no Monte Carlo: sigmas of the linearised problem do not
depend on the noise draw). Starts from the paper's 3-D run and changes the 660-720 s descent's duration
(0 = no descent: the 2-D case) and the DVL ping rate. Writes a plot and a CSV.

    .venv/bin/python examples/descent_study.py -o study/            # full grid (minutes)
    .venv/bin/python examples/descent_study.py -o study/ --quick    # 2 x 2 grid
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gtsam_dvl.analysis.planning import plan_mission  # noqa: E402
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict  # noqa: E402


def scenario_with(descent_s: float, dvl_hz: float) -> dict:
    """paper-3d with the descent lasting descent_s seconds (0: replaced by level cruise) at dvl_hz."""
    raw = copy.deepcopy(load_scenario("paper-3d").raw)
    raw["rates"]["dvl_hz"] = dvl_hz
    segments = []
    for seg in raw["segments"]:
        if seg["kind"] in ("descent", "ascent"):
            if descent_s <= 0:
                continue  # the vehicle stays level: the 2-D case
            seg = {**seg, "duration_s": float(descent_s)}
        segments.append(seg)
    raw["segments"] = segments
    return raw


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("-o", "--output", type=Path, default=Path("descent-study"))
    ap.add_argument("--quick", action="store_true", help="a 2 x 2 grid (for tests)")
    args = ap.parse_args()
    durations = [0.0, 60.0] if args.quick else [0.0, 15.0, 30.0, 60.0, 120.0]
    rates = [1.0, 2.0] if args.quick else [0.5, 1.0, 2.0]
    sigma = np.zeros((len(rates), len(durations)))
    for i, hz in enumerate(rates):
        for j, dur in enumerate(durations):
            plan = plan_mission(
                scenario_from_dict(scenario_with(dur, hz), f"descent-{dur:.0f}s-{hz:g}Hz")
            )
            sigma[i, j] = plan.report.state("misalignment_roll").posterior_sigma
            print(
                f"DVL {hz:>4.1f} Hz, descent {dur:>5.0f} s: roll misalignment sigma {sigma[i, j]:.3f} deg "
                f"({plan.report.state('misalignment_roll').verdict})",
                flush=True,
            )
    args.output.mkdir(parents=True, exist_ok=True)
    with open(args.output / "descent_study.csv", "w") as fh:
        fh.write("dvl_hz,descent_s,roll_sigma_deg\n")
        for i, hz in enumerate(rates):
            for j, dur in enumerate(durations):
                fh.write(f"{hz},{dur},{sigma[i, j]:.6f}\n")
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, hz in enumerate(rates):
        ax.plot(durations, sigma[i], "o-", label=f"DVL {hz:g} Hz")
    ax.axhline(1.0, color="0.5", ls="--", lw=0.8, label="prior (1 deg)")
    ax.set_xlabel("descent duration (s), peak sink rate 0.8 m/s")
    ax.set_ylabel("final sigma of the misalignment\nabout the thrust axis (deg)")
    ax.set_title("Thrust-axis misalignment: what a descent buys (paper-3d, covariance analysis)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.savefig(args.output / "descent_study.png", dpi=110, bbox_inches="tight")
    print(f"wrote {args.output / 'descent_study.png'} and {args.output / 'descent_study.csv'}")


if __name__ == "__main__":
    main()
