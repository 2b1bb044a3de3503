"""The report of a Monte Carlo campaign: report.md (a table per estimator: error/sigma, RMSE against sigma and
against the Cramer-Rao bound, NEES with its band) and its figures (error/sigma histograms, the filters' NEES
over time)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.app.campaign.montecarlo import BLOCK_DOF


def write_report(out_dir: Path, stats: dict[str, Any]) -> list[Path]:
    """report.md and the figures of a campaign's statistics."""
    from gtsam_dvl.io.atomic import atomic_write_text

    figs = plot_campaign(out_dir / "figures", stats)
    n = stats["runs"]
    lines = [
        f"# Monte Carlo campaign: {stats['scenario']}, {n} runs",
        "",
        "Error/sigma of each state over the runs (0 +- 1 when the sigmas are honest), the fraction within 3 "
        "sigma (99.7 % expected), the RMSE against the mean reported sigma and against the Cramer-Rao bound "
        "(noise-free batch information at the truth), and the NEES of the "
        f"{BLOCK_DOF}-dof calibration and bias block with its 95 % band for {n} runs.",
        "",
    ]
    for name, est in stats["estimators"].items():
        nb = est["nees_block"]
        lines += [
            f"## {name}",
            "",
            f"Mean wall time per run {est['wall_s_mean']:.2f} s. Block NEES mean {nb['mean']:.2f} "
            f"(band {nb['band_95'][0]:.2f}-{nb['band_95'][1]:.2f}): "
            f"{'inside' if nb['inside_band'] else '**outside**'}.",
            "",
            "| state | unit | mean z | std z | within 3 sigma | RMSE | mean sigma | RMSE/sigma | RMSE/CRB |",
            "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
        ]
        for state, r in est["states"].items():
            crb = f"{r['rmse_over_crb']:.2f}" if "rmse_over_crb" in r else "-"
            lines.append(
                f"| {state} | {r['unit']} | {r['z_mean']:+.2f} | {r['z_std']:.2f} | "
                f"{100 * r['within_3_sigma']:.0f} % | {r['rmse']:.4g} | {r['mean_sigma']:.4g} | "
                f"{r['rmse_over_sigma']:.2f} | {crb} |"
            )
        if "nees_time" in est:
            nt = est["nees_time"]
            lines += [
                "",
                f"NEES over time (diagonal, every 60 s): {100 * nt['fraction_inside']:.0f} % of the samples "
                f"inside the 95 % band {nt['band_95'][0]:.2f}-{nt['band_95'][1]:.2f}.",
            ]
        lines.append("")
    if stats.get("failures"):
        lines += (
            ["## Failed runs", ""]
            + [f"- seed {f['seed']}: {f['error']}" for f in stats["failures"]]
            + [""]
        )
    lines += ["## Figures", ""] + [f"![{p.stem}](figures/{p.name})" for p in figs] + [""]
    return [atomic_write_text(out_dir / "report.md", "\n".join(lines)), *figs]


def plot_campaign(fig_dir: Path, stats: dict[str, Any]) -> list[Path]:
    """Per estimator a grid of error/sigma histograms with the N(0, 1) density (from the runs' files), and the
    filters' NEES over time with the 95 % band."""
    import matplotlib.pyplot as plt

    from gtsam_dvl.app.plots.common import save_figure

    out: list[Path] = []
    runs_dir = fig_dir.parent / "runs"
    seeds = set(stats.get("seeds", []))
    runs = [
        r
        for r in (json.loads(p.read_text()) for p in sorted(runs_dir.glob("seed_*.json")))
        if r["seed"] in seeds
    ]
    for name, est in stats["estimators"].items():
        states = list(est["states"])
        rows = [r["estimators"][name] for r in runs if name in r["estimators"]]
        z = np.array([np.array(x["error"]) / np.array(x["sigma"]) for x in rows])
        if "time_offset" in states:
            z = np.column_stack(
                [z, [x["time_offset"]["error"] / x["time_offset"]["sigma"] for x in rows]]
            )
        cols = 4
        nrows = int(np.ceil(len(states) / cols))
        fig, axes = plt.subplots(nrows, cols, figsize=(12, 2.4 * nrows + 0.6), squeeze=False)
        grid = np.linspace(-4, 4, 200)
        for j, state in enumerate(states):
            ax = axes[j // cols, j % cols]
            ax.hist(
                np.clip(z[:, j], -4, 4),
                bins=np.linspace(-4, 4, 17),
                density=True,
                color="0.7",
                edgecolor="0.4",
                label="runs",
            )
            ax.plot(
                grid,
                np.exp(-0.5 * grid**2) / np.sqrt(2 * np.pi),
                color="C3",
                lw=1.2,
                label="N(0, 1)",
            )
            ax.set_title(f"{state}: std {est['states'][state]['z_std']:.2f}", fontsize=8)
            ax.set_xlabel("error / sigma (-)", fontsize=7)
            ax.set_ylabel("density (-)", fontsize=7)
            ax.tick_params(labelsize=7)
        for j in range(len(states), nrows * cols):
            axes[j // cols, j % cols].axis("off")
        axes[0, 0].legend(fontsize=7)
        fig.suptitle(f"{name}: error/sigma over {len(rows)} runs (clipped to +-4)")
        out.append(save_figure(fig, fig_dir / f"z_histograms_{name}.png"))
        if "nees_time" in est:
            nt = est["nees_time"]
            fig, ax = plt.subplots(figsize=(9, 3.5))
            ax.plot(nt["t"], nt["mean"], color="C0", label=f"{name}: mean NEES over the runs")
            ax.axhspan(*nt["band_95"], color="0.85", label="95 % band")
            ax.axhline(10, color="0.4", ls="--", lw=0.8, label="dof (10)")
            ax.set_yscale("log")
            ax.set_xlabel("time (s)")
            ax.set_ylabel("NEES (-)")
            ax.legend(fontsize=8)
            ax.set_title(f"{name}: NEES of scale, misalignment and biases over time (diagonal)")
            out.append(save_figure(fig, fig_dir / f"nees_time_{name}.png"))
    return out
