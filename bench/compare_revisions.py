"""This checkout against another git revision, in one run: bench_factors.py and bench_batch.py run alternately in
both trees, several rounds, each figure the best of its rounds, and the ratio this / base.

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
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FACTOR_ROW = re.compile(r"^(dvl_velocity|dvl_beam)\s+([0-9.]+)\s+[0-9.]+\s+([0-9.]+)\s*$", re.M)
BATCH_TOTAL = re.compile(r"^total \(read to marginals\)\s+([0-9.]+)", re.M)


def run(tree: Path, script: str, *args: str) -> str:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, str(tree / "bench" / script), *args], cwd=tree, env=env,
                         capture_output=True, text=True, check=True)
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
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", default="HEAD~1", help="the git revision to compare against (default HEAD~1)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of both trees, alternating (default 3)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(base), args.base], cwd=ROOT, check=True)
        try:
            best: dict[str, dict[str, float]] = {"this": {}, "base": {}}
            for r in range(args.rounds):
                for name, tree in (("base", base), ("this", ROOT)) if r % 2 == 0 else (("this", ROOT), ("base", base)):
                    for k, v in figures(tree).items():
                        best[name][k] = min(v, best[name].get(k, float("inf")))
                print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, check=False)
    print(f"best of {args.rounds} rounds; base {args.base}")
    print(f"{'figure':<42}{'this':>10}{'base':>10}{'this/base':>11}")
    for k in best["this"]:
        this, old = best["this"][k], best["base"][k]
        print(f"{k:<42}{this:>10.3f}{old:>10.3f}{this / old:>11.2f}")


if __name__ == "__main__":
    main()
