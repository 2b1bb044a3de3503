"""What ``read_log(..., salvage=True)`` reports about the chunks it had to drop.

The scan itself lives in ``mcap_scan`` (salvage is the same walk over the data section, tolerant of a
missing footer and of chunks whose CRC fails). A dropped chunk's log-time span comes from its header,
its message count from its MessageIndex records, or for a cut-off last chunk from decompressing what
is there (then "at least").
"""

from __future__ import annotations

from gtsam_dvl.io.storage.sources import Source


def salvage_report(src: Source, t0_ns: int) -> str:
    """One line: chunks kept and lost, messages lost, log-time span lost (s relative to t0_ns)."""
    losses = src.losses
    total = src.chunk_count()
    chunks = [x for x in losses if x.start_ns is not None]
    if not losses:
        return f"salvage: {src.path}: all {total} chunks intact, nothing lost" if total else (
            f"salvage: {src.path}: no MCAP chunks to check, nothing lost")
    msgs = sum(x.messages for x in losses)
    exact = all(x.exact for x in losses)
    text = (
        f"salvage: {src.path}: kept {total - len(chunks)} of {total} chunks; lost {len(chunks)} chunk(s) "
        f"with {'' if exact else 'at least '}{msgs} message(s)"
    )
    if chunks:
        a = min(int(x.start_ns) for x in chunks if x.start_ns is not None)
        b = max(int(x.end_ns) for x in chunks if x.end_ns is not None)
        text += f", log time {(a - t0_ns) / 1e9:.3f} s to {(b - t0_ns) / 1e9:.3f} s"
    if len(chunks) < len(losses):
        text += "; the end of the file is unreadable"
    return text
