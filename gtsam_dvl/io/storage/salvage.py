"""What ``read_log(..., salvage=True)`` reports about the data it could not read.

The scan itself lives in ``mcap_scan`` (salvage is the same walk over the data section, tolerant of a
missing footer and of chunks whose CRC fails). A dropped chunk's log-time span comes from its header,
its message count (per topic) from its MessageIndex records, or for a cut-off last chunk from decompressing
what is there (then "at least"). A file without footer was cut short: everything recorded after the last
chunk read is missing, and how long the recording went on is not known (the summary at the end is gone).

``salvage_losses`` gives the structured record (``LogData.metadata["reader_losses"]["salvage"]``),
``salvage_report`` the one line of ``metadata["reader_warnings"]``.
"""

from __future__ import annotations

from typing import Any

from gtsam_dvl.io.storage.sources import Source


def _union_s(spans: list[tuple[float, float]]) -> float:
    total, end = 0.0, float("-inf")
    for a, b in sorted(spans):
        if b > end:
            total += b - max(a, end)
            end = b
    return total


def salvage_losses(src: Source, t0_ns: int) -> dict[str, Any]:
    """Chunks kept and lost, messages lost (in all and per topic), the log-time spans lost (s relative to
    t0_ns) and the files that were cut short (byte, log time up to which data was read)."""
    losses = src.losses
    chunks = [x for x in losses if x.start_ns is not None]
    per_topic: dict[str, int] = {}
    for x in losses:
        for topic, n in x.per_topic.items():
            per_topic[topic] = per_topic.get(topic, 0) + n
    spans = [
        ((int(x.start_ns) - t0_ns) / 1e9, (int(x.end_ns) - t0_ns) / 1e9)
        for x in chunks
        if x.start_ns is not None and x.end_ns is not None
    ]
    truncated = []
    for part in src.parts:
        if not getattr(part, "complete", True):
            end_ns = part.kept_end_ns()  # type: ignore[union-attr]  # McapScan: the only storage without footer
            truncated.append(
                {
                    "file": str(part.path),
                    "at_byte": len(part.buf),  # type: ignore[union-attr]
                    "data_end_s": None if end_ns is None else (end_ns - t0_ns) / 1e9,
                }
            )
    total = src.chunk_count()
    return {
        "chunks_total": total,
        "chunks_kept": total - len(chunks),
        "chunks_lost": len(chunks),
        "messages_lost": sum(x.messages for x in losses),
        "messages_lost_exact": all(x.exact for x in losses),
        "messages_lost_per_topic": per_topic,
        "lost_spans_s": [list(s) for s in spans],
        "seconds_lost": _union_s(spans),
        "truncated": truncated,
        "end_unreadable": len(chunks) < len(losses),
        "anything_lost": bool(losses) or bool(truncated),
    }


def salvage_report(losses: dict[str, Any], path: object) -> str:
    """One line from salvage_losses: chunks kept and lost, messages lost (per topic), log-time span lost,
    where the file was cut."""
    total = losses["chunks_total"]
    if not losses["anything_lost"]:
        return (
            f"salvage: {path}: all {total} chunks intact, nothing lost"
            if total
            else (f"salvage: {path}: no MCAP chunks to check, nothing lost")
        )
    lost = losses["chunks_lost"]
    if lost:
        at_least = "" if losses["messages_lost_exact"] else "at least "
        text = (
            f"salvage: {path}: kept {losses['chunks_kept']} of {total} chunks; lost {lost} chunk(s) with "
            f"{at_least}{losses['messages_lost']} message(s)"
        )
        if per := losses["messages_lost_per_topic"]:
            text += " (" + ", ".join(f"{t} {n}" for t, n in sorted(per.items())) + ")"
        if spans := losses["lost_spans_s"]:
            text += (
                f", log time {min(s[0] for s in spans):.3f} s to {max(s[1] for s in spans):.3f} s "
                f"({losses['seconds_lost']:.1f} s of data)"
            )
    else:
        text = f"salvage: {path}: kept all {total} chunks"
    for cut in losses["truncated"]:
        end = cut["data_end_s"]
        where = (
            f"nothing after log time {end:.3f} s could be read"
            if end is not None
            else "no chunk could be read"
        )
        spans = losses["lost_spans_s"]
        beyond = max((s[1] for s in spans), default=None)
        went_on = (
            f"the recording went on to at least {beyond:.3f} s, "
            if beyond is not None and (end is None or beyond > end)
            else ""
        )
        text += (
            f"; the file is cut short at byte {cut['at_byte']} (no footer): {where}; {went_on}how long it "
            "went on after that is unknown"
        )
    if losses["end_unreadable"] and not losses["truncated"]:
        text += "; the end of the file is unreadable"
    return text
