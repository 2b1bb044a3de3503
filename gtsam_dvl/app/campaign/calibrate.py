"""`gtsam-dvl calibrate LOG... -o calib.toml`: one vehicle calibration from several dives, on Dask.

Each dive is a chain of Dask tasks on one worker (estimators/batch/multi_dive.py has the method): the first reads the
log
and smooths it alone (prepare_dive) and returns the dive's DiveState, which stays in that worker's memory; every
joint iteration then submits, per dive, a task on that future that linearises the dive and eliminates its own
variables (reduce_dive: only the small reduction comes back) and, once the client has solved for the shared step,
one that back-substitutes it (advance_dive). The graph is built once per dive and never shipped: each task is pinned
to the worker that holds its dive (a DiveState holds GTSAM objects, which do not pickle). A dive whose task raises
(a bad log, a graph that cannot be solved) is reported with its error and left out; the others finish.

Without Dask, or with --workers 1 and no --scheduler, the same steps run in this process.

The per-dive table and figure: each dive alone against the joint calibration (analysis/fleet_calibration.py).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.analysis.fleet_calibration import DiveVsJoint, dive_vs_joint
from gtsam_dvl.app.campaign.cluster import LOCAL_CLUSTER, DaskEngine, finished
from gtsam_dvl.core.calibration import SourceLog, VehicleCalibration, config_hash, iso_date
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import misalignment_rpy_and_cov
from gtsam_dvl.estimators.batch.multi_dive import (
    TOL,
    DiveState,
    DiveSummary,
    JointSolution,
    Reduction,
    advance_dive,
    iterate_joint,
    joint_setup,
    prepare_dive,
    reduce_dive,
    set_shared,
    summarise,
)

if TYPE_CHECKING:
    from gtsam_dvl.io.read_options import ReadOptions


def _error_text(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, GtsamDvlError) else f"{type(exc).__name__}: {exc}"


# ----- the tasks (module level: Dask ships them by reference) -------------------------------------------------


def prepare_task(
    log_path: str, config_path: str | None, read_options: ReadOptions | None
) -> DiveState:
    """Read a log and prepare its dive (estimators/batch/multi_dive.py prepare_dive) with the configuration given, or
    the one the log's scenario names, as `smooth` chooses it."""
    from gtsam_dvl.app.commands import load_log
    from gtsam_dvl.core.config import estimator_overrides

    log = load_log(log_path, read_options)
    config = (
        EstimatorConfig.load(Path(config_path), under=estimator_overrides(log.metadata))
        if config_path
        else EstimatorConfig.for_log(log.metadata)
    )
    return prepare_dive(log, config, name=log_path)


def summary_task(dive: DiveState) -> DiveSummary:
    return summarise(dive)


def start_task(dive: DiveState, values: dict[str, np.ndarray]) -> DiveState:
    set_shared(dive, values)
    return dive


def reduce_task(dive: DiveState) -> Reduction:
    return reduce_dive(dive)


def advance_task(dive: DiveState, ds: np.ndarray, values: dict[str, np.ndarray]) -> DiveState:
    advance_dive(dive, ds, values)
    return dive


# ----- where the dives run ----------------------------------------------------------------------------------


@dataclass
class DiveFailure:
    """A dive left out: its log and its error line."""

    log: str
    error: str


class LocalDives:
    """The dives in this process."""

    def __init__(
        self,
        logs: list[str],
        config_path: str | None,
        read_options: ReadOptions | None,
        failures: list[DiveFailure],
    ) -> None:
        self.failures = failures
        self.dives: list[DiveState] = []
        for p in logs:
            try:
                self.dives.append(prepare_task(p, config_path, read_options))
            except Exception as exc:  # noqa: BLE001 - one dive's failure must not stop the others: reported
                failures.append(DiveFailure(p, _error_text(exc)))

    def summaries(self) -> list[DiveSummary]:
        return [summarise(d) for d in self.dives]

    def start(self, values: dict[str, np.ndarray]) -> None:
        for d in self.dives:
            set_shared(d, values)

    def reduce_all(self) -> list[Reduction]:
        out, keep = [], []
        for d in self.dives:
            try:
                out.append(reduce_dive(d))
                keep.append(d)
            except Exception as exc:  # noqa: BLE001 - reported, the dive left out
                self.failures.append(DiveFailure(d.name, _error_text(exc)))
        self.dives = keep
        return out

    def advance_all(self, ds: np.ndarray, values: dict[str, np.ndarray]) -> None:
        keep = []
        for d in self.dives:
            try:
                advance_dive(d, ds, values)
                keep.append(d)
            except Exception as exc:  # noqa: BLE001 - reported, the dive left out
                self.failures.append(DiveFailure(d.name, _error_text(exc)))
        self.dives = keep

    def names(self) -> list[str]:
        return [d.name for d in self.dives]


class DaskDives:
    """The dives as Dask futures, each pinned to the worker that holds its DiveState (module doc)."""

    def __init__(
        self,
        client: Any,
        logs: list[str],
        config_path: str | None,
        read_options: ReadOptions | None,
        failures: list[DiveFailure],
        progress: Any = None,
    ) -> None:
        self.client, self.failures = client, failures
        futures = {
            client.submit(prepare_task, p, config_path, read_options, pure=False): p for p in logs
        }
        done: dict[str, Any] = {}
        for p, fut, exc in finished(futures, progress):
            if exc is not None:
                failures.append(DiveFailure(p, _error_text(exc)))
            else:
                done[p] = fut
        where = client.who_has(list(done.values()))
        # (log, future, worker) in the order the logs were given
        self.entries: list[tuple[str, Any, str]] = [
            (p, done[p], where[done[p].key][0]) for p in logs if p in done
        ]

    def _submit(self, func: Any, fut: Any, worker: str, *args: Any) -> Any:
        return self.client.submit(
            func, fut, *args, workers=[worker], allow_other_workers=False, pure=False
        )

    def summaries(self) -> list[DiveSummary]:
        return self.client.gather([self._submit(summary_task, f, w) for _, f, w in self.entries])

    def start(self, values: dict[str, np.ndarray]) -> None:
        self.entries = [(p, self._submit(start_task, f, w, values), w) for p, f, w in self.entries]

    def reduce_all(self) -> list[Reduction]:
        from dask.distributed import wait

        futs = [self._submit(reduce_task, f, w) for _, f, w in self.entries]
        wait(futs)
        out, keep = [], []
        for entry, fut in zip(self.entries, futs, strict=True):
            if fut.status == "error":
                self.failures.append(DiveFailure(entry[0], _error_text(fut.exception())))
            else:
                out.append(fut.result())
                keep.append(entry)
        self.entries = keep
        return out

    def advance_all(self, ds: np.ndarray, values: dict[str, np.ndarray]) -> None:
        self.entries = [
            (p, self._submit(advance_task, f, w, ds, values), w) for p, f, w in self.entries
        ]

    def names(self) -> list[str]:
        return [p for p, _, _ in self.entries]


# ----- the command ------------------------------------------------------------------------------------------


@dataclass
class CalibrateOutcome:
    """What `calibrate` made: the calibration (None when every dive failed), the joint solution, each dive
    kept (its summary alone and its comparison with the joint), the dives left out, wall times (s)."""

    calibration: VehicleCalibration | None
    solution: JointSolution | None
    dives: list[DiveSummary]
    comparisons: list[DiveVsJoint]
    failures: list[DiveFailure]
    engine: str
    timing_s: dict[str, float] = field(default_factory=dict)
    written: list[Path] = field(default_factory=list)

    def describe(self) -> str:
        lines = fleet_table(self)
        if self.solution is not None:
            h = self.solution.history
            lines.append(
                f"\n{len(self.dives)} dives, {self.solution.iterations} joint iterations "
                f"({'converged' if self.solution.converged else 'NOT converged'}: last step "
                f"{h[-1]['step_sigma']:.2g} sigma), {self.engine}, {self.timing_s.get('total', 0):.1f} s"
            )
        for f in self.failures:
            lines.append(
                f"left out: {f.error if f.error.startswith(f.log) else f'{f.log}: {f.error}'}"
            )
        lines += [f"wrote {p}" for p in self.written]
        return "\n".join(lines)


def run_dives(
    dives: LocalDives | DaskDives, tol: float = TOL
) -> tuple[JointSolution | None, list[DiveSummary], dict[str, float]]:
    """The joint iterations over prepared dives (in-process or on Dask)."""
    t0 = time.perf_counter()
    summaries = dives.summaries()
    if not summaries:
        return None, [], {}
    names, start, prior = joint_setup(summaries)
    dives.start(start)
    solution = iterate_joint(names, start, prior, dives.reduce_all, dives.advance_all, tol)
    kept = set(dives.names())
    return solution, [s for s in summaries if s.name in kept], {"joint": time.perf_counter() - t0}


def calibrate_logs(
    logs: list[Path],
    output: Path | None = None,
    config_path: Path | None = None,
    read_options: ReadOptions | None = None,
    engine: DaskEngine = LOCAL_CLUSTER,
    vehicle: str = "vehicle",
    out_dir: Path | None = None,
    tol: float = TOL,
    show_progress: bool = True,
    client: Any = None,
) -> CalibrateOutcome:
    """`gtsam-dvl calibrate`: the dives' joint calibration written to `output` (io/calibration_file.py), the
    per-dive table and figure to out_dir (calibration-fleet.md, .json, .png). On Dask (the engine's LocalCluster
    or scheduler, or a client given), in this process with engine.workers == 1 and no scheduler, or when Dask is
    missing and no scheduler was asked for."""
    if not logs:
        raise GtsamDvlError("no logs given")
    for p in logs:
        if not Path(p).exists():
            raise GtsamDvlError(f"{p}: no such file or directory")
    paths = [str(Path(p).resolve()) for p in logs]
    cfg = str(Path(config_path).resolve()) if config_path else None
    options = read_options
    failures: list[DiveFailure] = []
    t0 = time.perf_counter()
    where, solution, summaries, timing, prepared = _solve(
        paths,
        cfg,
        options,
        failures,
        tol,
        show_progress,
        client,
        engine,
        t0,
    )
    timing = {"prepare": prepared, **timing, "total": time.perf_counter() - t0}
    outcome = CalibrateOutcome(None, solution, summaries, [], failures, where, timing)
    if solution is None:
        return outcome
    joint = solution.estimates()
    outcome.comparisons = [
        dive_vs_joint(s.name, solution.states, s.alone, joint, s.alone_cov, solution.cov)
        for s in summaries
    ]
    outcome.calibration = _joint_calibration(solution, summaries, vehicle)
    if output is not None:
        from gtsam_dvl.io.calibration_file import write_calibration

        outcome.written.append(write_calibration(output, outcome.calibration))
    if out_dir is not None:
        outcome.written += write_fleet(outcome, Path(out_dir))
    return outcome


def _solve(
    paths: list[str],
    cfg: str | None,
    options: ReadOptions | None,
    failures: list[DiveFailure],
    tol: float,
    show_progress: bool,
    client: Any,
    engine: DaskEngine,
    t0: float,
) -> tuple[str, JointSolution | None, list[DiveSummary], dict[str, float], float]:
    """The dives smoothed alone and solved jointly: in this process (no client, no scheduler, and one worker or
    no Dask), on the client given, or on the engine's Dask cluster (a scheduler's, else a LocalCluster).
    Returns where they ran, in words, the joint solution (None: no dive left), the dives' summaries, the timing and
    the seconds from t0 to the dives prepared."""
    from gtsam_dvl.app.progress import progress_bar

    here = client is None and engine.scheduler is None and (engine.workers == 1 or not _has_dask())
    with _where(here, client, engine) as (where, on):
        started = t0 if on is None else time.perf_counter()  # on Dask: from the client up
        dives: LocalDives | DaskDives
        with progress_bar(f"smoothing {len(paths)} dives alone", enabled=show_progress) as progress:
            if on is None:
                dives = LocalDives(paths, cfg, options, failures)
                progress(1.0)
            else:
                dives = DaskDives(on, paths, cfg, options, failures, progress)
        prepared = time.perf_counter() - started
        solution, summaries, timing = run_dives(dives, tol)
        if on is not None and show_progress and solution is not None:
            sys.stderr.write(f"joint: {solution.iterations} iterations\n")
    return where, solution, summaries, timing, prepared


@contextmanager
def _where(here: bool, client: Any, engine: DaskEngine) -> Iterator[tuple[str, Any]]:
    """Where the dives run, in words, and the Dask client they run on (None: in this process): the client
    given, else the engine's (a scheduler's, or a LocalCluster), closed on exit."""
    if here:
        yield "in this process", None
    elif client is not None:
        yield "Dask", client
    else:
        with engine.client() as c:
            yield f"Dask ({len(c.scheduler_info().get('workers', {}))} workers)", c


def _joint_calibration(
    solution: JointSolution, summaries: list[DiveSummary], vehicle: str
) -> VehicleCalibration:
    """The joint solution as the vehicle's calibration: dated by its latest dive, the dives its sources."""
    return VehicleCalibration(
        vehicle=vehicle,
        date=iso_date(max(s.t0_ns for s in summaries)),
        states=tuple(solution.states),
        values={n: np.asarray(v, dtype=float) for n, v in solution.values.items()},
        cov=solution.cov,
        sources=tuple(SourceLog(s.name, _sha256(s.name)) for s in summaries),
        config_hash=config_hash(summaries[0].stated_config or summaries[0].config.to_dict()),
        method="calibrate",
        notes={
            "dives": len(summaries),
            "iterations": solution.iterations,
            "converged": solution.converged,
        },
    )


def _has_dask() -> bool:
    import importlib.util

    return (
        importlib.util.find_spec("dask") is not None
        and importlib.util.find_spec("distributed") is not None
    )


def _sha256(path: str) -> str:
    from gtsam_dvl.io.result_writer import file_sha256

    return file_sha256(path)


# ----- the fleet table and figure ---------------------------------------------------------------------------


def fleet_rows(outcome: CalibrateOutcome) -> list[dict[str, Any]]:
    """One row per dive (and one for the joint calibration): scale, misalignment (deg, R_c's roll, pitch, yaw),
    time offset with sigmas, and the comparison with the joint (per state chi^2, dof, sigmas, moved; the block's
    chi^2; analysis/fleet_calibration.py)."""
    rows: list[dict[str, Any]] = []
    for s, c in zip(outcome.dives, outcome.comparisons, strict=True):
        b_R_d0 = np.asarray(s.mounting.b_R_d0)
        rpy, cov = misalignment_rpy_and_cov(
            np.asarray(s.alone["misalignment"].value),
            b_R_d0,
            np.asarray(s.alone["misalignment"].cov),
        )
        off = s.alone.get("time_offset")
        rows.append(
            {
                "log": s.name,
                "scale": float(s.alone["scale"].value[0]),
                "scale_sigma": float(s.alone["scale"].sigma[0]),
                "misalignment_deg": rpy.tolist(),
                "misalignment_sigma_deg": np.sqrt(np.diag(cov)).tolist(),
                "time_offset_s": None if off is None else float(off.value[0]),
                "time_offset_sigma_s": None if off is None else float(off.sigma[0]),
                "chi2": c.chi2,
                "dof": c.dof,
                "n_sigma": c.n_sigma,
                "moved": c.moved,
                "moved_states": c.moved_states(),
                "vs_joint": {
                    n: {
                        "chi2": m.chi2,
                        "dof": m.dof,
                        "n_sigma": m.n_sigma,
                        "moved": m.moved,
                        "residual_display": m.residual_display.tolist(),
                    }
                    for n, m in c.states.items()
                },
            }
        )
    if outcome.solution is not None and outcome.dives:
        j = outcome.solution.estimates()
        rpy, cov = misalignment_rpy_and_cov(
            np.asarray(j["misalignment"].value),
            np.asarray(outcome.dives[0].mounting.b_R_d0),
            np.asarray(j["misalignment"].cov),
        )
        rows.append(
            {
                "log": "joint",
                "scale": float(j["scale"].value[0]),
                "scale_sigma": float(j["scale"].sigma[0]),
                "misalignment_deg": rpy.tolist(),
                "misalignment_sigma_deg": np.sqrt(np.diag(cov)).tolist(),
                "time_offset_s": None,
                "time_offset_sigma_s": None,
                "dives": len(outcome.dives),
            }
        )
    return rows


def fleet_table(outcome: CalibrateOutcome) -> list[str]:
    """The per-dive table in Markdown (the fleet table's columns, app/campaign/fleet.py, plus each dive against
    the joint calibration), the joint calibration last, the dives left out with their errors."""
    lines = [
        "| dive | scale | misalignment r/p/y (deg) | time offset (ms, + = stamps early) | "
        "vs joint (sigmas, per state) | moved beyond 3 sigma |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for r in fleet_rows(outcome):
        mis = (
            " ".join(f"{v:+.3f}" for v in r["misalignment_deg"])
            + " +- "
            + " ".join(f"{v:.3f}" for v in r["misalignment_sigma_deg"])
        )
        off = (
            "-"
            if r["time_offset_s"] is None
            else f"{r['time_offset_s'] * 1e3:+.1f} +- {r['time_offset_sigma_s'] * 1e3:.1f}"
        )
        if r["log"] == "joint":
            lines.append(
                f"| **joint ({r['dives']} dives)** | {r['scale']:.5f} +- {r['scale_sigma']:.5f} | {mis} | "
                "per dive | | |"
            )
            continue
        vs = ", ".join(
            f"{n.replace('_', ' ')} {m['n_sigma']:.1f}" for n, m in r["vs_joint"].items()
        )
        moved = (
            (
                "MOVED: "
                + ", ".join(
                    f"{n.replace('_', ' ')} {r['vs_joint'][n]['n_sigma']:.1f} sigma"
                    for n in r["moved_states"]
                )
            )
            if r["moved"]
            else "no"
        )
        lines.append(
            f"| {Path(r['log']).name} | {r['scale']:.5f} +- {r['scale_sigma']:.5f} | {mis} | {off} | "
            f"{vs} | {moved} |"
        )
    for f in outcome.failures:
        lines.append(f"| {Path(f.log).name} | error | {f.error} | | | |")
    return lines


def plot_fleet(outcome: CalibrateOutcome, path: Path) -> Path:
    """Per dive the scale and the misalignment's roll, pitch, yaw alone with 3 sigma bars, the joint calibration
    as a line with its 3 sigma band; a dive that moved in red."""
    from gtsam_dvl.app.plots.common import plt, save_figure

    rows = fleet_rows(outcome)
    dives, joint = rows[:-1], rows[-1]
    fig, axes = plt.subplots(1, 4, figsize=(13, 3.4))
    x = np.arange(len(dives))
    titles = ["scale (ppm from 1)"] + [f"misalignment {a} (deg)" for a in ("roll", "pitch", "yaw")]

    def get(r: dict[str, Any], panel: int) -> tuple[float, float]:
        if panel == 0:
            return (r["scale"] - 1) * 1e6, r["scale_sigma"] * 1e6
        return r["misalignment_deg"][panel - 1], r["misalignment_sigma_deg"][panel - 1]

    for panel, (ax, title) in enumerate(zip(axes, titles, strict=True)):
        jv, js = get(joint, panel)
        ax.axhspan(jv - 3 * js, jv + 3 * js, color="0.85", label="joint, 3 sigma")
        ax.axhline(jv, color="k", lw=1)
        for k, r in zip(x, dives, strict=True):
            v, s = get(r, panel)
            ax.errorbar(
                k, v, yerr=3 * s, fmt="o", capsize=3, color="tab:red" if r["moved"] else "tab:blue"
            )
        ax.set_xticks(x, [Path(r["log"]).stem for r in dives], rotation=45, ha="right", fontsize=7)
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    fig.suptitle(
        "Each dive alone (3 sigma) against the joint calibration; red: moved beyond 3 sigma",
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path)


def write_fleet(outcome: CalibrateOutcome, out_dir: Path) -> list[Path]:
    """out_dir/calibration-fleet.md, .json and .png."""
    from gtsam_dvl.io.atomic import atomic_write_json, atomic_write_text

    out_dir.mkdir(exist_ok=True)
    written = [
        atomic_write_text(out_dir / "calibration-fleet.md", "\n".join(fleet_table(outcome)) + "\n"),
        atomic_write_json(
            out_dir / "calibration-fleet.json",
            {
                "dives": fleet_rows(outcome),
                "failures": [f.__dict__ for f in outcome.failures],
                "iterations": outcome.solution.history if outcome.solution else [],
            },
        ),
    ]
    if outcome.dives:
        written.append(plot_fleet(outcome, out_dir / "calibration-fleet.png"))
    return written
