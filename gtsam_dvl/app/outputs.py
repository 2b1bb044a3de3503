"""Safe outputs: the checks every command makes on its output paths before any work (docs/command-line.md). An output
that is an input, lies inside an input bag folder, is given twice or cannot be written is refused (check_outputs);
an output file's folder must exist and an output folder is created only inside one that does (check_folders). Each
a one-line GtsamDvlError."""

from __future__ import annotations

import os
from pathlib import Path

from gtsam_dvl.core.errors import GtsamDvlError


def _same_file(a: Path, b: Path) -> bool:
    """Same file by inode when both exist (links, other spellings), else by resolved path."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_outputs(inputs: dict[str, Path | None], outputs: dict[str, Path | None]) -> None:
    """Before any work: refuse an output that is an input (the same file by path, link or inode), lies inside
    an input bag folder, or is given twice; and check that every output can be written there. inputs and
    outputs map a name for messages (e.g. "the input log", "--summary") to a path (None: not given)."""
    from gtsam_dvl.io.atomic import check_writable

    ins = {name: Path(p) for name, p in inputs.items() if p is not None}
    outs = {name: Path(p) for name, p in outputs.items() if p is not None}
    for name, out in outs.items():
        for in_name, inp in ins.items():
            if _same_file(out, inp):
                raise GtsamDvlError(
                    f"{out}: {name} is {in_name} ({inp}); writing it would destroy the input, "
                    "choose another output path"
                )
            if inp.is_dir() and out.resolve().is_relative_to(inp.resolve()):
                raise GtsamDvlError(
                    f"{out}: {name} lies inside {in_name}, the bag folder {inp}; write outputs "
                    "elsewhere"
                )
    items = list(outs.items())
    for i, (name, out) in enumerate(items):
        for other, path in items[i + 1 :]:
            if _same_file(out, path):
                raise GtsamDvlError(
                    f"{out}: given as both {name} and {other}; each output needs its own path"
                )
    for out in outs.values():
        check_writable(out)


def check_folders(
    files: dict[str, Path | None], folders: dict[str, Path | None] | None = None
) -> None:
    """The command line's rule for output paths (docs/command-line.md): the folder of an output file must exist
    (no folder tree is created for it, a mistyped path is refused); an output folder is created if missing, but
    only inside a folder that exists, and must not be a file. files / folders map the option's name to its path
    (None: not given). A one-line GtsamDvlError before any work."""
    for name, path in files.items():
        if path is not None and not Path(path).absolute().parent.exists():
            raise GtsamDvlError(
                f"{path}: no folder {Path(path).parent} for {name}; create it first (outputs "
                "never create folder trees)"
            )
    for name, path in (folders or {}).items():
        if path is None:
            continue
        path = Path(path)
        if path.exists() and not path.is_dir():
            raise GtsamDvlError(
                f"{path}: is a file, and {name} takes a folder; choose another path"
            )
        if not path.absolute().parent.exists():
            raise GtsamDvlError(
                f"{path}: no folder {path.parent} to create it in for {name}; create it first "
                "(outputs never create folder trees)"
            )
