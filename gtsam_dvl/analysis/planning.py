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

from gtsam_dvl.analysis.observability import (
    ObservabilityReport,
    analyse,
    attribute_segments,
    calibration_answer,
    determined_at,
)
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.types import Segment
from gtsam_dvl.estimators.batch.smoother import smooth_batch
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
        """The planner's answer in a navigator's words (observability.calibration_answer)."""
        return "\n".join(calibration_answer(self.report, self.determined_at_s, "plan"))


def plan_mission(
    scenario: Scenario,
    config: EstimatorConfig | None = None,
    seed: int = 0,
    progress: ProgressFn | None = None,
) -> PlanResult:
    """Covariance analysis of a scenario (see module doc); takes seconds."""
    start = time.perf_counter()
    config = config or scenario.estimator_configuration()
    if config.imu.bias_model != "constant":
        raise GtsamDvlError(
            "planning needs imu.bias_model = 'constant' (the filtering timeline of a random-walk "
            "bias is not implemented)"
        )
    log = simulate(scenario, seed, white_noise=False)
    if progress:
        progress(0.2)
    result = smooth_batch(
        log,
        config,
        timeline=True,
        estimator="plan",
        progress=(lambda f: progress(0.2 + 0.7 * f)) if progress else None,
    )
    assert result.timeline is not None  # asked for, with a constant bias
    timeline = result.timeline
    obs = analyse(result, config).for_plan()
    segments = log.segments
    shares = attribute_segments(obs, timeline, segments)
    if progress:
        progress(1.0)
    return PlanResult(
        scenario.name,
        result,
        timeline,
        obs,
        determined_at(obs, timeline),
        segments,
        shares,
        time.perf_counter() - start,
    )
