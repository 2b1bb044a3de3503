"""Open any log storage we accept: a bare .mcap, a bare .db3, or a rosbag2 bag directory
(metadata.yaml next to .mcap or .db3 files, e.g. written by ``ros2 bag record`` or ``rosbags``).

A .db3 is read with the standard library's sqlite3 (rosbag2's schema: tables ``topics`` and
``messages``, optionally ``message_definitions``), so no ROS installation is needed.

``read`` returns every body of the chosen topics at once; ``iter_read`` the same bodies in pieces (an MCAP's
chunks, pages of DB3_PAGE rows of a .db3), so that a reader decoding as it goes never holds them all.
"""

from __future__ import annotations

import re
import sqlite3
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.mcap.scan import McapScan
from gtsam_dvl.io.storage.raw import Bodies, Loss, TopicInfo

DB3_PAGE = 100_000  # rows of a .db3 fetched at a time by iter_read


class Db3Source:
    """One rosbag2 sqlite3 storage file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, tuple[str, bytes]] = {}
        self.warnings: list[str] = []
        self.losses: list[Loss] = []
        self._ids: dict[str, int] = {}
        self.topics: dict[str, TopicInfo] = {}
        try:
            self.con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
            tables = {
                r[0] for r in self.con.execute("SELECT name FROM sqlite_master WHERE type='table'")
            }
            defs: dict[str, str] = {}
            if "message_definitions" in tables:
                for tname, enc, text in self.con.execute(
                    "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
                ):
                    if enc == "ros2msg" and text:
                        defs[tname] = text
            for tid, name, tname, fmt in self.con.execute(
                "SELECT id, name, type, serialization_format FROM topics ORDER BY id"
            ):
                self._ids.setdefault(name, tid)
                self.topics.setdefault(name, TopicInfo(name, tname, defs.get(tname), fmt))
        except sqlite3.Error as e:
            raise GtsamDvlError(f"{path}: not a readable rosbag2 sqlite3 file ({e})") from None

    def chunk_count(self) -> int:
        return 0

    def message_counts(self) -> dict[str, int]:
        rows = self.con.execute(
            "SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id"
        ).fetchall()
        names = {v: k for k, v in self._ids.items()}
        return {names[t]: n for t, n in rows if t in names}

    def _rows(self, topic: str) -> sqlite3.Cursor:
        """The topic's (timestamp, data) rows in recording order, as a cursor (read fetches them all, iter_read
        page by page)."""
        return self.con.execute(
            "SELECT timestamp, data FROM messages WHERE topic_id = ? ORDER BY id",
            (self._ids[topic],),
        )

    def read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> dict[str, Bodies]:
        out: dict[str, Bodies] = {}
        wanted = [t for t in topics if t in self._ids]
        for i, topic in enumerate(wanted):
            try:
                rows = self._rows(topic).fetchall()
            except sqlite3.Error as e:
                raise GtsamDvlError(f"{self.path}: cannot read {topic} ({e})") from None
            out[topic] = _bodies(rows)
            if progress is not None:
                progress((i + 1) / len(wanted))
        return out

    def iter_read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> Iterator[dict[str, Bodies]]:
        """``read``'s bodies in pages of DB3_PAGE rows, topic after topic (each topic's in order)."""
        wanted = [t for t in topics if t in self._ids]
        for i, topic in enumerate(wanted):
            try:
                cur = self._rows(topic)
                while rows := cur.fetchmany(DB3_PAGE):
                    yield {topic: _bodies(rows)}
            except sqlite3.Error as e:
                raise GtsamDvlError(f"{self.path}: cannot read {topic} ({e})") from None
            if progress is not None:
                progress((i + 1) / len(wanted))


def _bodies(rows: list[tuple[int, bytes]]) -> Bodies:
    """Bodies of (timestamp, data) rows: one (N, L) array when all have one length."""
    t = np.array([r[0] for r in rows], dtype=np.int64)
    data = [bytes(r[1]) for r in rows]
    if data and len({len(d) for d in data}) == 1:
        return Bodies(t, fixed=np.frombuffer(b"".join(data), np.uint8).reshape(len(data), -1))
    return Bodies(t, var=data)


Storage = McapScan | Db3Source


class Source:
    """One or more storage files read as one log (split bags are concatenated in order)."""

    def __init__(self, path: Path, parts: list[Storage]) -> None:
        self.path, self.parts = path, parts
        self.topics: dict[str, TopicInfo] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, tuple[str, bytes]] = {}
        for p in parts:
            for k, v in p.topics.items():
                self.topics.setdefault(k, v)
            self.metadata.update(p.metadata)
            self.attachments.update(p.attachments)

    @property
    def warnings(self) -> list[str]:
        return [w for p in self.parts for w in p.warnings]

    @property
    def losses(self) -> list[Loss]:
        return [x for p in self.parts for x in p.losses]

    def chunk_count(self) -> int:
        return sum(p.chunk_count() for p in self.parts)

    def message_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for p in self.parts:
            for k, n in p.message_counts().items():
                out[k] = out.get(k, 0) + n
        return out

    def read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> dict[str, Bodies]:
        topics = list(topics)
        got: dict[str, list[Bodies]] = {}
        for i, p in enumerate(self.parts):
            sub = None if progress is None else (lambda f, i=i: progress((i + f) / len(self.parts)))
            for k, b in p.read(topics, sub).items():
                got.setdefault(k, []).append(b)
        return {k: v[0] if len(v) == 1 else Bodies.concat(v) for k, v in got.items()}

    def iter_read(
        self, topics: Iterable[str], progress: Callable[[float], None] | None = None
    ) -> Iterator[dict[str, Bodies]]:
        """``read``'s bodies piece by piece (the storage's chunks or pages), parts in order, each topic's
        bodies in file order."""
        topics = list(topics)
        for i, p in enumerate(self.parts):
            sub = None if progress is None else (lambda f, i=i: progress((i + f) / len(self.parts)))
            yield from p.iter_read(topics, sub)

    def describe_topics(self) -> str:
        return ", ".join(f"{k} [{v.type_name}]" for k, v in sorted(self.topics.items())) or "none"


def _bag_files(folder: Path) -> list[Path]:
    names: list[str] = []
    meta = folder / "metadata.yaml"
    if meta.is_file():
        m = re.search(
            r"relative_file_paths:[ \t]*\n((?:[ \t]*-[^\n]*\n?)+)", meta.read_text(errors="replace")
        )
        if m:
            names = [
                ln.split("-", 1)[1].strip().strip("'\"")
                for ln in m.group(1).splitlines()
                if ln.strip()
            ]
    files = [folder / Path(n).name for n in names] or sorted(
        [*folder.glob("*.mcap"), *folder.glob("*.db3")]
    )
    if not files:
        raise GtsamDvlError(f"{folder}: a folder without .mcap or .db3 files (not a rosbag2 bag)")
    if missing := [f.name for f in files if not f.exists()]:
        raise GtsamDvlError(
            f"{folder}: storage files listed in metadata.yaml are missing: {', '.join(missing)}"
        )
    if packed := [f.name for f in files if f.suffix in (".zstd", ".zst")]:
        raise GtsamDvlError(
            f"{folder}: file-compressed bag ({packed[0]}); run `ros2 bag decompress` first"
        )
    return files


def _open_file(path: Path, salvage: bool) -> Storage:
    with path.open("rb") as f:
        head = f.read(16)
    if head.startswith(b"\x89MCAP"):
        return McapScan(path, salvage=salvage)
    if head.startswith(b"SQLite format 3"):
        return Db3Source(path)
    raise GtsamDvlError(f"{path}: neither an MCAP nor a rosbag2 sqlite3 (.db3) file")


def open_source(path: str | Path, *, salvage: bool = False) -> Source:
    """The log at ``path``: .mcap, .db3 or a bag directory."""
    p = Path(path)
    if not p.exists():
        raise GtsamDvlError(f"{p}: no such file or directory")
    try:
        files = _bag_files(p) if p.is_dir() else [p]
        return Source(p, [_open_file(f, salvage) for f in files])
    except OSError as e:
        raise GtsamDvlError(f"{p}: cannot read ({e.strerror or e})") from None
