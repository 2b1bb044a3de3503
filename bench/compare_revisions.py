"""This checkout against another git revision, in one run: bench_factors.py and bench_batch.py run alternately in
both trees, several rounds, each figure the best and the median of its rounds, and the ratios this / base.

    .venv/bin/python bench/compare_revisions.py [--base HEAD~1] [--rounds 3]

The base revision is checked out into a temporary git worktree (removed at the end) and imported from there
(PYTHONPATH first on the path); both trees use this interpreter and its installed dependencies. Alternating the
two trees round by round spreads the machine's drift over both. Figures: the DVL CustomFactors' linearize and error
microseconds per factor (bench_factors.py: one ping, the per-factor path the online estimator uses) and the batch
smoother's read-to-marginals seconds on paper-3d (bench_batch.py, bulk path; its per-factor baseline skipped).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FACTOR_ROW = re.compile(r"^(dvl_velocity|dvl_beam)\s+([0-9.]+)\s+[0-9.]+\s+([0-9.]+)\s*$", re.M)
BATCH_TOTAL = re.compile(r"^total \(read to marginals\)\s+([0-9.]+)", re.M)


def run(tree: Path, script: str, *args: str) -> str:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run(
        [sys.executable, str(tree / "bench" / script), *args],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout


def figures(tree: Path) -> dict[str, float]:
    f: dict[str, float] = {}
    text = run(tree, "bench_factors.py")
    for name, lin, err in FACTOR_ROW.findall(text):
        f[f"{name} linearize (us)"] = float(lin)
        f[f"{name} error (us)"] = float(err)
    m = BATCH_TOTAL.search(run(tree, "bench_batch.py", "--no-baseline"))
    if m is None:
        raise SystemExit(f"bench_batch.py in {tree} printed no total")
    f["batch paper-3d read to marginals (s)"] = float(m.group(1))
    return f


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--base", default="HEAD~1", help="the git revision to compare against (default HEAD~1)"
    )
    ap.add_argument(
        "--rounds", type=int, default=3, help="rounds of both trees, alternating (default 3)"
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(
            ["git", "worktree", "add", "-q", "--detach", str(base), args.base], cwd=ROOT, check=True
        )
        try:
            seen: dict[str, dict[str, list[float]]] = {"this": {}, "base": {}}
            for r in range(args.rounds):
                for name, tree in (
                    (("base", base), ("this", ROOT))
                    if r % 2 == 0
                    else (("this", ROOT), ("base", base))
                ):
                    for k, v in figures(tree).items():
                        seen[name].setdefault(k, []).append(v)
                print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, check=False
            )
    print(f"{args.rounds} rounds; base {args.base}; best (min) and median of the rounds")
    print(
        f"{'figure':<40}{'this best':>10}{'base best':>10}{'ratio':>7}{'this med':>10}{'base med':>10}{'ratio':>7}"
    )
    for k, this in seen["this"].items():
        old = seen["base"][k]
        b_t, b_o, m_t, m_o = min(this), min(old), statistics.median(this), statistics.median(old)
        print(
            f"{k:<40}{b_t:>10.3f}{b_o:>10.3f}{b_t / b_o:>7.2f}{m_t:>10.3f}{m_o:>10.3f}{m_t / m_o:>7.2f}"
        )


if __name__ == "__main__":
    main()
