"""Fast raw MCAP reading: walk the records ourselves and hand back each topic's CDR bodies in bulk.

Why not ``mcap.reader``: it yields one Python object per message (and ``mcap_ros2`` decodes each into
more), which caps reading near 10^4-10^5 messages/s. Here each zstd chunk is decompressed once, the
message records are located from the chunk's MessageIndex records (or by walking the records when a
writer left them out), and a channel's bodies are cut out as one (N, L) uint8 array through a
sliding-window view. Only the data section is read, so the same walk serves ``salvage``: a file without
footer is scanned from the start and every chunk whose CRC checks is kept.

Memory: a file of MMAP_MIN_BYTES or more is memory-mapped, not read, and ``iter_read`` hands out
the bodies chunk by chunk, each chunk's compressed bytes released from the process's memory once it is
decompressed, so a reader that decodes as it goes holds one chunk and its own output, not the log.
"""

from __future__ import annotations

import mmap
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.mcap import container as mc
from gtsam_dvl.io.storage.raw import Bodies, Loss, TopicInfo

_win = np.lib.stride_tricks.sliding_window_view
SALVAGE_HINT = "rerun with --salvage to recover the intact chunks"
# files this large are memory-mapped (smaller ones are read: no difference then)
MMAP_MIN_BYTES = 16 << 20
Buf = bytes | mmap.mmap  # the file: read, or memory-mapped


@dataclass
class _Chunk:
    pos: int
    start_ns: int
    end_ns: int
    usize: int
    crc: int
    compression: str
    data: slice
    index: dict[int, int] = field(default_factory=dict)  # channel -> MessageIndex record position
    records: bytes | None = None  # decompressed, kept when the records had to be walked anyway
    offsets: np.ndarray | None = None  # message record offsets found by walking
    lost: bool = False


def _str(buf: Buf, off: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, off)
    return buf[off + 4 : off + 4 + n].decode(), off + 4 + n


def _map(buf: Buf, off: int) -> tuple[dict[str, str], int]:
    (n,) = struct.unpack_from("<I", buf, off)
    out, p, end = {}, off + 4, off + 4 + n
    while p < end:
        k, p = _str(buf, p)
        out[k], p = _str(buf, p)
    return out, end


def _walk_records(
    data: Buf, complete: bool = True, other: Callable[[int, Buf, int], None] | None = None
) -> list[int]:
    """Offsets of the Message records in a chunk's records; other records go to ``other(op, data,
    content_offset)``. A Python loop: used only for chunks without MessageIndex records, for files
    without summary (channel records may sit inside chunks) and for salvage."""
    offs, pos, n = [], 0, len(data)
    while pos + 9 <= n:
        op, ln = struct.unpack_from("<BQ", data, pos)
        if pos + 9 + ln > n:
            if complete:
                raise ValueError(f"record at {pos} overruns the chunk")
            break
        if op == mc.OP_MESSAGE:
            offs.append(pos)
        elif other is not None:
            other(op, data, pos + 9)
        pos += 9 + ln
    return offs


def _open_buffer(path: Path) -> Buf:
    """The file's bytes: memory-mapped (read-only) from MMAP_MIN_BYTES on, else read."""
    with path.open("rb") as f:
        size = path.stat().st_size
        if size < MMAP_MIN_BYTES:
            return f.read()
        return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)


class McapScan:
    """One MCAP file: topics, metadata, attachments; ``read`` returns the bodies of chosen topics."""

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path, self.salvage = path, salvage
        self.buf: Buf = _open_buffer(path)
        self.schemas: dict[int, tuple[str, str, str]] = {}
        self.channels: dict[int, TopicInfo] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, tuple[str, bytes]] = {}
        self.segments: list[_Chunk | list[int]] = []  # chunks, and runs of messages outside chunks
        self.losses: list[Loss] = []
        self.tail_chunk_lost = False
        self.complete = True  # False: no footer (a truncated file, read with salvage)
        self.warnings: list[str] = []
        self._zstd = zstandard.ZstdDecompressor()
        self._scan()

    @property
    def topics(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for info in self.channels.values():
            out.setdefault(info.topic, info)
        return out

    def _fail(self, pos: int, what: str) -> GtsamDvlError:
        return GtsamDvlError(f"{self.path}: {what} at byte {pos}; {SALVAGE_HINT}")

    def _scan(self) -> None:
        """Find the records: the data section's (chunks, messages outside chunks, metadata, attachments,
        definitions), then the summary section's definitions, then the channels inside the chunks when the
        summary gave none."""
        buf, n = self.buf, len(self.buf)
        if buf[:8] != mc.MAGIC:
            raise GtsamDvlError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")
        complete = n >= 45 and buf[-8:] == mc.MAGIC and buf[n - 37] == mc.OP_FOOTER
        self.complete = complete
        if not complete and not self.salvage:
            raise GtsamDvlError(
                f"{self.path}: truncated at byte {n} (footer missing); {SALVAGE_HINT}"
            )
        self._scan_data_section()
        if complete:
            self._scan_summary()
        if not self.channels or not complete:
            # Channel records may sit inside chunks (rosbag2, rosbags); without a summary, walk them.
            for seg in self.segments:
                if isinstance(seg, _Chunk) and (data := self._records(seg)) is not None:
                    seg.records = data
                    seg.offsets = self._walk(seg, data, definitions=True)

    def _scan_data_section(self) -> None:
        """The records after the magic up to the data end (or the footer): each read by _top_record; with salvage,
        a malformed record or a file cut inside one ends the scan with a loss recorded, else it is an error."""
        buf, n = self.buf, len(self.buf)
        pos = 8
        while pos + 9 <= n:
            op, ln = struct.unpack_from("<BQ", buf, pos)
            end = pos + 9 + ln
            try:
                if end > n or op == 0:
                    raise ValueError("record overruns the file")
                if op in (mc.OP_DATA_END, mc.OP_FOOTER):
                    break
                self._top_record(op, pos)
            except (ValueError, struct.error, UnicodeDecodeError):
                if not self.salvage:
                    raise self._fail(pos, "malformed record") from None
                self._lost_tail(pos, op, pos + 9)
                break
            pos = end
        else:
            if self.salvage and pos < n:
                self._lost_tail(pos, -1, pos + 9)

    def _scan_summary(self) -> None:
        """The schema and channel records of a complete file's summary section (a malformed one is an error
        unless salvage, which then goes without it)."""
        buf, n = self.buf, len(self.buf)
        (summary_start,) = struct.unpack_from("<Q", buf, n - 28)
        try:
            if summary_start:
                _walk_records(buf[summary_start : n - 37], other=self._definition)
        except (ValueError, struct.error, UnicodeDecodeError):
            if not self.salvage:
                raise self._fail(summary_start, "malformed summary section") from None

    def _top_record(self, op: int, pos: int) -> None:
        buf, c = self.buf, pos + 9
        if op == mc.OP_CHUNK:
            t0, t1, usize, crc = struct.unpack_from("<QQQI", buf, c)
            comp, p = _str(buf, c + 28)
            (clen,) = struct.unpack_from("<Q", buf, p)
            if p + 8 + clen > len(buf):
                raise ValueError("chunk overruns the file")
            self.segments.append(_Chunk(pos, t0, t1, usize, crc, comp, slice(p + 8, p + 8 + clen)))
        elif op == mc.OP_MESSAGE_INDEX and self.segments and isinstance(self.segments[-1], _Chunk):
            self.segments[-1].index[struct.unpack_from("<H", buf, c)[0]] = pos
        elif op == mc.OP_MESSAGE:
            if not self.segments or isinstance(self.segments[-1], _Chunk):
                self.segments.append([])
            seg = self.segments[-1]
            assert isinstance(seg, list)
            seg.append(pos)
        elif op == mc.OP_METADATA:
            name, p = _str(buf, c)
            self.metadata[name], _ = _map(buf, p)
        elif op == mc.OP_ATTACHMENT:
            name, p = _str(buf, c + 16)
            media, p = _str(buf, p)
            (size,) = struct.unpack_from("<Q", buf, p)
            self.attachments[name] = (media, buf[p + 8 : p + 8 + size])
        else:
            self._definition(op, buf, c)

    def _definition(self, op: int, buf: Buf, c: int) -> None:
        """Schema and Channel records, wherever they are (data section, chunks, summary)."""
        if op == mc.OP_SCHEMA:
            (sid,) = struct.unpack_from("<H", buf, c)
            name, p = _str(buf, c + 2)
            enc, p = _str(buf, p)
            data, _ = _str(buf, p)
            self.schemas[sid] = (name, enc, data)
        elif op == mc.OP_CHANNEL:
            cid, sid = struct.unpack_from("<HH", buf, c)
            topic, p = _str(buf, c + 4)
            enc, p = _str(buf, p)
            meta, _ = _map(buf, p)
            name, senc, text = self.schemas.get(sid, ("", "", ""))
            self.channels[cid] = TopicInfo(
                topic, name, text if senc == "ros2msg" else None, enc, meta
            )

    def _lost_tail(self, pos: int, op: int, c: int) -> None:
        """Salvage: the file ends (or turns to garbage) inside the record at ``pos``."""
        buf = self.buf
        if op == mc.OP_CHUNK and c + 16 <= len(buf):
            t0, t1 = struct.unpack_from("<QQ", buf, c)
            count, per_topic = 0, dict[str, int]()
            if c + 40 <= len(buf):
                comp, p = _str(buf, c + 28)
                part = b""
                if comp == "zstd":
                    try:
                        part = zstandard.ZstdDecompressor().decompressobj().decompress(buf[p + 8 :])
                    except zstandard.ZstdError:
                        part = b""
                elif comp == "":
                    part = buf[p + 8 :]
                offs = _walk_records(part, complete=False)
                count = len(offs)
                for off in offs:
                    if off + 11 <= len(part):
                        topic = self._topic_of(struct.unpack_from("<H", part, off + 9)[0])
                        per_topic[topic] = per_topic.get(topic, 0) + 1
            self.losses.append(Loss(pos, t0, t1, count, False, per_topic))
            self.tail_chunk_lost = True
        else:
            self.losses.append(Loss(pos, None, None, 0, False))

    def _records(self, ch: _Chunk) -> bytes | None:
        """The chunk's decompressed records, None (and a recorded loss) if salvage drops it."""
        if ch.records is not None or ch.lost:
            return ch.records
        raw = self.buf[ch.data]
        try:
            if ch.compression == "zstd":
                data = self._zstd.decompress(raw, max_output_size=ch.usize)
            elif ch.compression == "":
                data = raw
            elif ch.compression == "lz4":
                try:
                    import lz4.frame  # type: ignore[import-not-found]
                except ImportError:
                    raise GtsamDvlError(
                        f"{self.path}: lz4-compressed chunks need the lz4 package"
                    ) from None
                data = lz4.frame.decompress(raw)
            else:
                raise GtsamDvlError(f"{self.path}: unknown chunk compression '{ch.compression}'")
            ok = len(data) == ch.usize and (ch.crc == 0 or zlib.crc32(data) == ch.crc)
        except (zstandard.ZstdError, RuntimeError):
            ok = False
        if ok:
            return data
        if not self.salvage:
            raise self._fail(ch.pos, "corrupt chunk (CRC or decompression failed)")
        per_topic: dict[str, int] = {}
        for cid, p in ch.index.items():
            topic = self._topic_of(cid)
            per_topic[topic] = (
                per_topic.get(topic, 0) + struct.unpack_from("<I", self.buf, p + 11)[0] // 16
            )
        self.losses.append(
            Loss(ch.pos, ch.start_ns, ch.end_ns, sum(per_topic.values()), bool(ch.index), per_topic)
        )
        ch.lost = True
        return None

    def _topic_of(self, cid: int) -> str:
        return self.channels[cid].topic if cid in self.channels else f"channel {cid}"

    def kept_end_ns(self) -> int | None:
        """The last log time of the chunks read intact (None without any)."""
        ends = [s.end_ns for s in self.segments if isinstance(s, _Chunk) and not s.lost]
        return max(ends) if ends else None

    def chunk_count(self) -> int:
        """Chunks in the file, including a cut-off last one."""
        return sum(isinstance(s, _Chunk) for s in self.segments) + int(self.tail_chunk_lost)

    def read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> dict[str, Bodies]:
        """Bodies of every message on ``topics`` (present ones), in file order."""
        topics = set(topics)
        pieces: dict[str, list[Bodies]] = {
            info.topic: [] for info in self.channels.values() if info.topic in topics
        }
        for got in self.iter_read(topics, progress):
            for t, b in got.items():
                pieces[t].append(b)
        return {t: Bodies.concat(p) for t, p in pieces.items()}

    def iter_read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> Iterator[dict[str, Bodies]]:
        """The bodies of ``topics`` one chunk (or run of messages outside chunks) at a time, in file order;
        topics without messages in a chunk are left out of its dict. The compressed chunk is dropped from
        memory once decompressed (a memory-mapped file's pages are given back)."""
        topics = set(topics)
        want = {cid: info.topic for cid, info in self.channels.items() if info.topic in topics}
        file_u8 = np.frombuffer(self.buf, np.uint8)
        for seg in self.segments:
            pieces: dict[str, list[Bodies]] = {t: [] for t in want.values()}
            if isinstance(seg, list):
                self._extract(file_u8, np.array(seg, dtype=np.int64), want, pieces, None)
                yield {t: p[0] if len(p) == 1 else Bodies.concat(p) for t, p in pieces.items() if p}
                continue
            data = self._records(seg)
            self._release(seg.data)
            if data is not None:
                u8 = np.frombuffer(data, np.uint8)
                if seg.offsets is not None:
                    offsets = seg.offsets
                elif seg.index:
                    offs = [self._index_offsets(seg.index[c]) for c in want if c in seg.index]
                    offsets = np.concatenate(offs) if offs else np.zeros(0, np.int64)
                    if len(offsets) and (offsets.min() < 0 or offsets.max() + 31 > len(u8)):
                        # the message index (outside the chunk, without a CRC) is damaged, the chunk is intact
                        # (its CRC held): find the messages by walking the chunk's own records instead
                        offsets = self._walk(seg, data)
                else:
                    offsets = self._walk(seg, data)
                self._extract(u8, offsets, want, pieces, seg)
                seg.records = None  # free it: read once
            if progress is not None:
                progress(seg.data.stop / len(self.buf))
            yield {t: p[0] if len(p) == 1 else Bodies.concat(p) for t, p in pieces.items() if p}

    def _release(self, span: slice) -> None:
        """Give back the resident pages of a memory-mapped span (they are re-read from the file if needed)."""
        if isinstance(self.buf, mmap.mmap) and hasattr(mmap, "MADV_DONTNEED"):
            start = span.start - span.start % mmap.PAGESIZE
            if span.stop > start:
                self.buf.madvise(mmap.MADV_DONTNEED, start, span.stop - start)

    def _walk(self, seg: _Chunk, data: bytes, definitions: bool = False) -> np.ndarray:
        try:
            return np.array(
                _walk_records(data, other=self._definition if definitions else None), np.int64
            )
        except (ValueError, struct.error, UnicodeDecodeError):
            raise self._fail(seg.pos, "malformed chunk records") from None

    def _index_offsets(self, pos: int) -> np.ndarray:
        (nbytes,) = struct.unpack_from("<I", self.buf, pos + 11)
        entries = np.frombuffer(
            self.buf, dtype=[("t", "<u8"), ("o", "<u8")], count=nbytes // 16, offset=pos + 15
        )
        return entries["o"].astype(np.int64)

    def _extract(
        self,
        u8: np.ndarray,
        offsets: np.ndarray,
        want: dict[int, str],
        pieces: dict[str, list[Bodies]],
        seg: _Chunk | None,
    ) -> None:
        if not len(offsets):
            return
        offs = np.sort(offsets)
        if offs[0] < 0 or offs[-1] + 31 > len(u8):
            raise self._fail(
                seg.pos if seg else int(offs[-1]), "message index points outside the chunk"
            )
        hdr = _win(u8, 31)[offs].view(mc.MESSAGE_HEADER)[:, 0]
        lens = hdr["len"].astype(np.int64) - 22
        if (
            (hdr["op"] != mc.OP_MESSAGE).any()
            or (offs + 31 + lens > len(u8)).any()
            or (lens < 0).any()
        ):
            raise self._fail(seg.pos if seg else int(offs[0]), "malformed message records")
        for cid, topic in want.items():
            sel = np.flatnonzero(hdr["channel"] == cid)
            if not len(sel):
                continue
            o, n = offs[sel] + 31, lens[sel]
            t = hdr["log_time"][sel].astype(np.int64)
            if (n == n[0]).all():
                rows = _win(u8, int(n[0]))[o] if n[0] > 0 else np.zeros((len(o), 0), np.uint8)
                pieces[topic].append(Bodies(t, fixed=rows))
            else:
                pieces[topic].append(
                    Bodies(t, var=[u8[a : a + b].tobytes() for a, b in zip(o, n, strict=True)])
                )

    def time_range(self) -> tuple[int, int]:
        """(first, last) log time over the chunks, ns; (0, 0) without chunks."""
        chunks = [s for s in self.segments if isinstance(s, _Chunk)]
        return (
            (min(c.start_ns for c in chunks), max(c.end_ns for c in chunks)) if chunks else (0, 0)
        )

    def message_counts(self) -> dict[str, int]:
        """Messages per topic from the MessageIndex records (chunks without them are not counted)."""
        counts: dict[str, int] = {}
        for seg in self.segments:
            if isinstance(seg, _Chunk):
                for cid, p in seg.index.items():
                    topic = self.channels[cid].topic
                    counts[topic] = (
                        counts.get(topic, 0) + struct.unpack_from("<I", self.buf, p + 11)[0] // 16
                    )
        return counts
