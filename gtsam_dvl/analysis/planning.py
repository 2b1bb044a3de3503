"""Mission planning by covariance analysis: will this plan calibrate the DVL, and when?

The scenario is simulated without white noise (biases, scale and misalignment kept) and smoothed once by
the batch smoother, whose solution is the truth to within a fraction of a sigma; its marginals give the final
sigmas, its filtering timeline over the same linearisation gives the sigma timeline, and the observability
analysis gives the verdict. Sigmas of a
linear-Gaussian problem do not depend on the noise realisation, so no Monte Carlo is needed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from gtsam_dvl.analysis.observability import ObservabilityReport, analyse, attribute_segments, determined_at
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.types import Segment
from gtsam_dvl.estimators.batch import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario


@dataclass
class PlanResult:
    scenario: str
    result: NavResult  # final sigmas (smoother marginals)
    timeline: Timeline  # filtering sigmas over time
    report: ObservabilityReport
    determined_at_s: dict[str, float | None]
    segments: list[Segment]
    shares: dict[str, list[tuple[str, float]]] = field(default_factory=dict)
    wall_s: float = 0.0

    def answer(self) -> str:
        """The planner's answer in a navigator's words."""
        dvl = ["scale", "misalignment_roll", "misalignment_pitch", "misalignment_yaw"]
        missing = [s for s in self.report.states if s.key in dvl and s.verdict != "determined"]
        lines = []
        if not missing:
            last = max(self.determined_at_s[k] or 0.0 for k in dvl)
            lines.append(f"Yes: this plan calibrates the DVL (scale and all three misalignment angles); the last "
                         f"of them is determined {last:.0f} s into the mission.")
        else:
            names = "; ".join(s.description for s in missing)
            lines.append(f"No: this plan leaves {names} {missing[0].verdict}.")
            if any(s.key == "misalignment_roll" for s in missing):
                lines.append("  The misalignment about the thrust axis needs a specific-force change off that axis: "
                             "add a descent or ascent (ballast) with constant attitude.")
        for s in self.report.states:
            when = self.determined_at_s.get(s.key)
            lines.append(f"  {s.sentence()}" + (f"; determined at {when:.0f} s" if when is not None else ""))
        return "\n".join(lines)


def plan_mission(scenario: Scenario, config: EstimatorConfig | None = None, seed: int = 0,
                 progress: ProgressFn | None = None) -> PlanResult:
    """Covariance analysis of a scenario (see module doc); takes seconds."""
    start = time.perf_counter()
    config = config or scenario.estimator_configuration()
    if config.imu.bias_model != "constant":
        raise GtsamDvlError("planning needs imu.bias_model = 'constant' (the filtering timeline of a random-walk "
                            "bias is not implemented)")
    log = simulate(scenario, seed, white_noise=False)
    if progress:
        progress(0.2)
    result = smooth_batch(log, config, timeline=True, estimator="plan",
                          progress=(lambda f: progress(0.2 + 0.7 * f)) if progress else None)
    assert result.timeline is not None  # asked for, with a constant bias
    timeline = result.timeline
    obs = analyse(result, config).for_plan()
    segments = log.segments
    shares = attribute_segments(obs, timeline, segments)
    if progress:
        progress(1.0)
    return PlanResult(scenario.name, result, timeline, obs, determined_at(obs, timeline), segments, shares,
                      time.perf_counter() - start)
