"""Atomic file writes: a temporary file in the target folder, then a rename, so that an interrupted
run never leaves a half-written result under its final name.

`OutputSet` writes the outputs of one run as a set: each goes to a temporary file in its folder, and all are
renamed into place together at the end (`commit`); if anything fails before (an exception, or SIGTERM turned
into one by the command line) every temporary file is removed and no output appears. While the set is renamed,
a signal handler that asks `deferring()` can postpone the signal (`defer`) until the renames are done.

Files are created with mode 0o666 minus the umask, as `open()` would create them (not mkstemp's 0o600), so
results are readable by the group like the MCAP logs. Errors are one-line GtsamDvlError naming the user's
path, never the temporary one.
"""

from __future__ import annotations

import abc
import contextlib
import json
import os
import secrets
import signal
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, Self

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError

_deferral = {"depth": 0, "pending": 0}


def deferring() -> bool:
    """True while an OutputSet renames its files: a signal handler should call defer() and return."""
    return _deferral["depth"] > 0


def defer(signum: int) -> None:
    """Remember a signal that arrived while renaming; it is raised again when the renames are done."""
    _deferral["pending"] = int(signum)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    _deferral["depth"] += 1
    try:
        yield
    finally:
        _deferral["depth"] -= 1
        if _deferral["depth"] == 0 and (signum := _deferral["pending"]):
            _deferral["pending"] = 0
            signal.raise_signal(signum)


def _cannot_write(path: Path, exc: OSError) -> GtsamDvlError:
    return GtsamDvlError(f"{path}: cannot write ({exc.strerror or exc})")


def _mkdir(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise GtsamDvlError(
            f"{path}: cannot create its folder {path.parent} ({e.strerror or e})"
        ) from None


def temp_path(path: Path) -> Path:
    """A fresh hidden name next to path (.<name>.<random>.tmp), not yet created."""
    return path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"


def _create_temp(path: Path) -> tuple[int, Path]:
    """Create a new temporary file next to path with mode 0o666 & ~umask; (fd, its path)."""
    for _ in range(100):
        tmp = temp_path(path)
        try:
            return os.open(
                tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666
            ), tmp
        except FileExistsError:
            continue
        except OSError as e:
            raise _cannot_write(path, e) from None
    raise GtsamDvlError(f"{path}: cannot create a temporary file next to it")


@contextlib.contextmanager
def _removed_on_failure(tmp: Path, path: Path) -> Iterator[None]:
    """If the block raises, tmp is removed and an OSError becomes the one-line error naming path."""
    try:
        yield
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise


def _write_temp(path: Path, data: bytes) -> Path:
    """data into a new temporary file next to path (folder created); returns the temporary path. Call with
    signals deferred, so that no signal falls between creating the file and the caller taking charge of it."""
    _mkdir(path)
    fd, tmp = _create_temp(path)
    with _removed_on_failure(tmp, path), os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    return tmp


def atomic_write_bytes(path: Path | str, data: bytes) -> Path:
    path = Path(path)
    with _signals_deferred():  # small files: a signal waits until the file is in place or removed
        tmp = _write_temp(path, data)
        with _removed_on_failure(tmp, path):
            os.replace(tmp, path)
    return path


def atomic_write_text(path: Path | str, text: str) -> Path:
    return atomic_write_bytes(path, text.encode())


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_json(data: Any) -> str:
    return json.dumps(data, indent=2, default=_json_default, allow_nan=True)


def atomic_write_json(path: Path | str, data: Any) -> Path:
    return atomic_write_text(path, to_json(data) + "\n")


def tum_text(t_abs_s: np.ndarray, n_p: np.ndarray, n_q_b_xyzw: np.ndarray) -> str:
    """TUM trajectory text (t x y z qx qy qz qw per line), as evo reads it."""
    rows = np.column_stack([t_abs_s, n_p, n_q_b_xyzw])
    return (
        "\n".join(
            " ".join(f"{v:.9f}" if j == 0 else f"{v:.9g}" for j, v in enumerate(r)) for r in rows
        )
        + "\n"
    )


def write_tum(
    path: Path | str, t_abs_s: np.ndarray, n_p: np.ndarray, n_q_b_xyzw: np.ndarray
) -> Path:
    """TUM trajectory file (t x y z qx qy qz qw per line), as evo reads it."""
    return atomic_write_text(path, tum_text(t_abs_s, n_p, n_q_b_xyzw))


def _remove_with_helpers(tmp: Path) -> None:
    """Remove tmp and the writer's own temporaries of it (.<tmp name>.*, as McapLogWriter names them: a signal
    can stop a writer before it could clean up)."""
    tmp.unlink(missing_ok=True)
    for helper in tmp.parent.glob(f".{tmp.name}.*"):
        helper.unlink(missing_ok=True)


class AtomicWriter(abc.ABC):
    """A writer whose files appear under their final names only on close(); abort() drops what it wrote. As a
    context manager: closed when the block ends, aborted when it raises."""

    @abc.abstractmethod
    def close(self) -> None: ...

    @abc.abstractmethod
    def abort(self) -> None: ...

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class OutputSet(AtomicWriter):
    """The outputs of one run, all or none (module doc). Use as a context manager: the files are renamed into
    place when the block ends without an exception, and removed when it raises.

        with OutputSet() as out:
            out.write_json(summary_path, summary)
            with out.staged(mcap_path) as tmp:   # for writers that need a path
                write_result_log(tmp, ...)
    """

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path]] = []  # (temporary, final)
        self.committed: list[Path] = []  # the final paths, once commit() has renamed them

    @property
    def paths(self) -> list[Path]:
        """The final paths, in the order they were staged."""
        return [final for _, final in self._staged]

    def write_bytes(self, path: Path | str, data: bytes) -> Path:
        path = Path(path)
        with _signals_deferred():
            self._staged.append((_write_temp(path, data), path))
        return path

    def write_text(self, path: Path | str, text: str) -> Path:
        return self.write_bytes(path, text.encode())

    def write_json(self, path: Path | str, data: Any) -> Path:
        return self.write_text(path, to_json(data) + "\n")

    @contextlib.contextmanager
    def staged(self, path: Path | str) -> Iterator[Path]:
        """A temporary path next to ``path`` for a writer that writes files itself (e.g. McapLogWriter). An error
        inside the block removes it and names ``path``, not the temporary file."""
        path = Path(path)
        _mkdir(path)
        tmp = temp_path(path)
        try:
            yield tmp
        except GtsamDvlError as exc:
            _remove_with_helpers(tmp)
            raise GtsamDvlError(str(exc).replace(str(tmp), str(path))) from None
        except OSError as exc:
            _remove_with_helpers(tmp)
            raise _cannot_write(path, exc) from None
        except BaseException:
            _remove_with_helpers(tmp)
            raise
        with _signals_deferred():
            if not tmp.exists():
                raise GtsamDvlError(f"{path}: the writer wrote nothing")
            self._staged.append((tmp, path))

    def commit(self) -> list[Path]:
        """Rename every staged file into place (signals deferred meanwhile). If a rename fails, the files already
        renamed are removed again, so that the set stays all or none."""
        done: list[Path] = []
        with _signals_deferred():
            try:
                for tmp, final in self._staged:
                    os.replace(tmp, final)
                    done.append(final)
            except OSError as exc:
                failed = self._staged[len(done)][1]
                for final in done:
                    final.unlink(missing_ok=True)
                self.abort()
                raise _cannot_write(failed, exc) from None
        self._staged = []
        self.committed = done
        return done

    def abort(self) -> None:
        """Remove every staged temporary file; nothing appears."""
        for tmp, _ in self._staged:
            _remove_with_helpers(tmp)
        self._staged = []

    def close(self) -> None:
        """commit(): the end of the with block."""
        self.commit()


def check_writable(path: Path | str) -> None:
    """Raise a one-line GtsamDvlError unless a file can be written at path: not a folder, its folder exists (or
    can be created under a writable folder) and accepts a new file (tried, then removed)."""
    path = Path(path)
    if path.is_dir():
        raise GtsamDvlError(f"{path}: is a folder, not a file path")
    folder = path.parent
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise GtsamDvlError(f"{path}: cannot create its folder ({existing} is a file)")
    if existing != folder:
        if not os.access(existing, os.W_OK | os.X_OK):
            raise GtsamDvlError(f"{path}: cannot create its folder ({existing} is not writable)")
        return
    with _signals_deferred():  # the probe file must not outlive a signal
        try:
            fd, tmp = _create_temp(path)
        except GtsamDvlError:
            raise GtsamDvlError(f"{path}: cannot write into {folder} (not writable)") from None
        os.close(fd)
        tmp.unlink(missing_ok=True)
