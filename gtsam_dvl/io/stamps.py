"""The stamp rules of the reader, one for every topic: stamps must increase (check_stamps), and a long step is
missing data (stamp_gaps).

check_stamps raises a one-line GtsamDvlError on a NaN message, a duplicate stamp or a stamp going backwards, or
with repair drops those messages and says how many; stamp_gaps finds the stretches a topic is missing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError

REPAIR_HINT = "rerun with --repair to drop such messages"
# A step between stamps this many times the topic's median spacing is missing data, not jitter (a 100 Hz IMU:
# 0.05 s; a 1 Hz DVL: 5 s). Such gaps are reported in metadata["reader_losses"]["gaps"] and as a warning.
GAP_FACTOR = 5.0
MAX_GAP_SPANS = 20  # spans listed per topic (the count and the seconds cover all of them)


def check_stamps(
    path: Path,
    topic: str,
    ns: np.ndarray,
    t0: int,
    bad: np.ndarray | None,
    repair: bool,
    warnings: list[str],
    dropped: dict[str, dict[str, int]] | None = None,
) -> np.ndarray:
    """Keep-mask of messages: raise on NaN (``bad``), duplicate or backwards stamps, or with ``repair``
    drop them and record how many in ``warnings`` (and by reason in ``dropped[topic]``)."""
    bad = np.zeros(len(ns), bool) if bad is None else bad

    def t(i: int) -> float:
        return (int(ns[i]) - t0) / 1e9

    if not repair:
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise GtsamDvlError(
                f"{path}: {topic}: NaN in message {i} (t = {t(i):.6f} s); {REPAIR_HINT}"
            )
        d = np.diff(ns)
        if (d <= 0).any():
            i = int(np.flatnonzero(d <= 0)[0]) + 1
            what = "duplicate stamp" if d[i - 1] == 0 else "time goes backwards"
            after = "" if d[i - 1] == 0 else f" after {t(i - 1):.9f} s"
            raise GtsamDvlError(
                f"{path}: {topic}: {what} at message {i} (t = {t(i):.9f} s{after}); {REPAIR_HINT}"
            )
        return np.ones(len(ns), bool)
    keep = ~bad
    idx = np.flatnonzero(keep)
    run_max = np.maximum.accumulate(ns[idx])
    later = np.concatenate([[True], ns[idx][1:] > run_max[:-1]])
    dup = int((ns[idx][1:] == run_max[:-1]).sum())
    keep[idx[~later]] = False
    if (n_drop := len(ns) - int(keep.sum())) > 0:
        warnings.append(
            f"{topic}: dropped {n_drop} message(s): {int(bad.sum())} with NaN, {dup} duplicate stamp(s), "
            f"{n_drop - int(bad.sum()) - dup} going back in time"
        )
        if dropped is not None:
            dropped[topic] = {
                "dropped": n_drop,
                "nan": int(bad.sum()),
                "duplicate": dup,
                "backwards": n_drop - int(bad.sum()) - dup,
                "of": len(ns),
            }
    return keep


def stamp_gaps(t: np.ndarray) -> dict[str, Any] | None:
    """Missing data in one topic's stamps (s): steps longer than GAP_FACTOR times the median spacing, their
    count, the seconds missing (each step minus one spacing) and the first MAX_GAP_SPANS spans; None if none."""
    if len(t) < 3:
        return None
    d = np.diff(t)
    period = float(np.median(d))
    big = np.flatnonzero(d > GAP_FACTOR * period)
    if period <= 0 or not len(big):
        return None
    return {
        "count": len(big),
        "seconds": float((d[big] - period).sum()),
        "period_s": period,
        "longest_s": float(d[big].max()),
        "spans_s": [[float(t[i]), float(t[i + 1])] for i in big[:MAX_GAP_SPANS].tolist()],
    }


def gap_warning(topic: str, gap: dict[str, Any]) -> str:
    """The warning line of a topic's gaps (stamp_gaps): how many, the seconds missing, the longest span."""
    a, b = max(gap["spans_s"], key=lambda s: s[1] - s[0])
    return (
        f"{topic}: {gap['count']} gap(s) in the data, {gap['seconds']:.1f} s missing in all "
        f"(longest {a:.2f} s to {b:.2f} s)"
    )
