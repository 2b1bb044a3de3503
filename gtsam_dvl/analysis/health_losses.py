"""What the reader lost, in the health check's words (analysis/health.py): LogData.metadata["reader_losses"] (what
--salvage and --repair dropped, gaps in the stamps, IMU saturation, clock steps) as figures and (severity, text)
findings.

Pure computation on the losses record: no files (analysis layer).
"""

from __future__ import annotations

from typing import Any

from gtsam_dvl.core.imu_faults import saturation_words
from gtsam_dvl.estimators.inputs.clock_evidence import evidence_words

# More than this share of a topic's messages dropped by --repair: the log is damaged, not just untidy.
REPAIRED_DEGRADED = 0.01
# IMU gaps are crossed by holding the last sample before them, with the motion model's uncertainty added
# (estimators/inputs/gaps.py): honest, but the trajectory across a gap longer than this is a guess the user should
# know about (a 100 Hz IMU dropping a few samples is harmless).
IMU_GAP_DEGRADED_S = 0.5
# The DVL may fall silent for a while (turns, bottom out of range); longer than this the trajectory is dead
# reckoned for long enough that the user should know where.
DVL_GAP_DEGRADED_S = 60.0


def loss_figures(losses: dict[str, Any]) -> dict[str, Any]:
    """The numbers of the reader's losses: messages lost per topic, seconds of data missing per topic (gaps in
    the stamps), chunks lost, whether the file was cut short and where its data end."""
    salv = losses.get("salvage") or {}
    return {
        "messages_lost": dict(losses.get("messages_lost", {})),
        "seconds_missing": {t: g["seconds"] for t, g in (losses.get("gaps") or {}).items()},
        "chunks_lost": salv.get("chunks_lost", 0),
        "truncated": bool(salv.get("truncated")),
        "data_end_s": min(
            (c["data_end_s"] for c in salv.get("truncated", []) if c["data_end_s"] is not None),
            default=None,
        ),
    }


def loss_lines(losses: dict[str, Any]) -> list[str]:
    """What the reader lost (LogData.metadata["reader_losses"]), one line per finding; [] if nothing."""
    return [text for _, text in loss_findings(losses)]


def loss_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """(severity, text) per loss: salvaged chunks, a cut-off file, messages dropped by --repair per topic, gaps
    in a topic's stamps, IMU saturation, clock steps. Severity "degraded" when the loss harms the result, else
    "note"."""
    return [
        *_salvage_findings(losses),
        *_repair_findings(losses),
        *_gap_findings(losses),
        *_saturation_findings(losses),
        *_clock_step_findings(losses),
        *_stamp_step_findings(losses),
    ]


def _salvage_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The chunks --salvage dropped and a file cut short: both degrade the result."""
    out: list[tuple[str, str]] = []
    salv = losses.get("salvage") or {}
    if salv.get("chunks_lost"):
        per = ", ".join(
            f"{t} {n}" for t, n in sorted(salv.get("messages_lost_per_topic", {}).items())
        )
        spans = salv.get("lost_spans_s", [])
        when = (
            (
                f", log time {min(s[0] for s in spans):.1f} to {max(s[1] for s in spans):.1f} s "
                f"({salv.get('seconds_lost', 0.0):.1f} s of data)"
            )
            if spans
            else ""
        )
        at_least = "" if salv.get("messages_lost_exact") else "at least "
        out.append(
            (
                "degraded",
                f"--salvage dropped {salv['chunks_lost']} damaged chunk(s) with {at_least}"
                f"{salv.get('messages_lost', 0)} message(s)"
                + (f" ({per})" if per else "")
                + when
                + ": the result has no data there",
            )
        )
    for cut in salv.get("truncated", []):
        end = cut.get("data_end_s")
        out.append(
            (
                "degraded",
                f"the log file is cut short at byte {cut['at_byte']}: nothing after "
                + (f"{end:.1f} s" if end is not None else "its start")
                + " could be read and how much more it held is unknown; the result ends there",
            )
        )
    return out


def _per_topic(losses: dict[str, Any], kind: str) -> list[tuple[str, Any]]:
    """(topic, record) of one kind of loss (losses[kind], absent or None: none), in the topics' name order."""
    return sorted((losses.get(kind) or {}).items())


def _repair_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The messages --repair dropped per topic: "degraded" beyond REPAIRED_DEGRADED of the topic."""
    return [_repair_finding(topic, d) for topic, d in _per_topic(losses, "repair")]


def _repair_finding(topic: str, d: dict[str, int]) -> tuple[str, str]:
    line = _repair_line(topic, d)
    if d.get("of") and d["dropped"] / d["of"] > REPAIRED_DEGRADED:
        return "degraded", line + ": the log is damaged, check the recording"
    return "note", line


def _gap_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The gaps in each topic's stamps: "degraded" when the longest is beyond the IMU's or the DVL's limit."""
    return [_gap_finding(topic, g) for topic, g in _per_topic(losses, "gaps")]


def _gap_finding(topic: str, g: dict[str, Any]) -> tuple[str, str]:
    line = _gap_line(topic, g)
    if "imu" in topic.lower():
        if g["longest_s"] > IMU_GAP_DEGRADED_S:
            return "degraded", line + (
                ": the IMU has holes, crossed by holding the last sample (the sigmas grow there); "
                "check the IMU driver"
            )
    elif g["longest_s"] > DVL_GAP_DEGRADED_S:
        return "degraded", line + ": dead reckoning on the IMU alone there"
    return "note", line


def _saturation_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The IMU's saturated stretches per topic (dropped and crossed as gaps): each degrades the result. In the
    reader's words for them (core/imu_faults.py saturation_words), with what it means for the result."""
    return [
        (
            "degraded",
            f"{topic}: {saturation_words(report)}, dropped and crossed as IMU gaps, holding the last "
            "sample before (the sigmas grow there); an IMU with a larger range avoids it",
        )
        for topic, report in _per_topic(losses, "saturation")
    ]


def _clock_step_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The clock steps --repair, or the estimators' screen of a log built in memory, shifted the stamps across:
    notes, with the DVL's evidence where it was judged (estimators/inputs/clock_evidence.py)."""
    out: list[tuple[str, str]] = []
    for topic, steps in _per_topic(losses, "clock_steps"):
        for c in steps:
            back = c["jump_s"] < 0
            if "decision" in c:
                who = (
                    "the DVL's timing across it"
                    if c["decision"] == "clock step"
                    else "the IMU's samples (the DVL cannot tell)"
                )
                done = f"shown by {who}: {evidence_words(c)}; the later stamps shifted"
            else:
                done = "--repair shifted the later stamps"
            out.append(
                (
                    "note",
                    f"{topic}: clock step at {c['at_s']:.3f} s (the stamps jump {'back ' * back}by "
                    f"{abs(c['jump_s']):.3f} s while the samples run on), {done} "
                    f"{'forward' if back else 'back'} by {abs(c['step_s']):.3f} s",
                )
            )
    return out


def _stamp_step_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The IMU stamp steps of a log built in memory that stayed as they were: a gap the DVL's timing confirms
    (a note: the gap itself is reported), or undecided ("degraded": if it was a clock step, everything after it
    is off by the step)."""
    out: list[tuple[str, str]] = []
    for topic, steps in _per_topic(losses, "imu_stamp_steps"):
        for c in steps:
            jump = f"{'back ' * (c['jump_s'] < 0)}by {abs(c['jump_s']):.3f} s"
            if c["decision"] == "gap":
                out.append(
                    (
                        "note",
                        f"{topic}: the stamps jump {jump} at {c['at_s']:.3f} s: samples missing, not a clock "
                        f"step ({evidence_words(c)})",
                    )
                )
            else:
                out.append(
                    (
                        "degraded",
                        f"{topic}: the stamps jump {jump} at {c['at_s']:.3f} s: a gap or a clock step of "
                        f"{c['step_s']:+.3f} s, undecided ({evidence_words(c)}); left as it is (a gap), "
                        "everything after it is off by the step if it was a clock step: check the IMU's stamps",
                    )
                )
    return out


def _repair_line(topic: str, d: dict[str, int]) -> str:
    why = ", ".join(
        f"{d[k]} {name}"
        for k, name in (
            ("nan", "with NaN"),
            ("duplicate", "duplicate stamp(s)"),
            ("backwards", "going back in time"),
        )
        if d.get(k)
    )
    return f"--repair dropped {d['dropped']} of {d.get('of', '?')} {topic} message(s) ({why})"


def _gap_line(topic: str, g: dict[str, Any]) -> str:
    a, b = (
        max(g["spans_s"], key=lambda s: s[1] - s[0])
        if g.get("spans_s")
        else (float("nan"), float("nan"))
    )
    return f"{topic}: {g['seconds']:.1f} s of data missing in {g['count']} gap(s) (longest {a:.1f} to {b:.1f} s)"
