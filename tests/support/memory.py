"""Weak references to what a method returns, for the tests that check what the estimators free."""

from __future__ import annotations

import gc
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest


@dataclass
class Made:
    """Weak references to every object made while a method was tracked."""

    refs: list[weakref.ref[Any]] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.refs)

    def alive(self) -> int:
        """How many of them are still alive once the garbage collector has run."""
        gc.collect()
        return sum(r() is not None for r in self.refs)


def track_returns(
    monkeypatch: pytest.MonkeyPatch,
    owner: type,
    name: str,
    part: Callable[[Any], Any] = lambda out: out,
) -> Made:
    """Patch the method owner.name (for the test's duration) to keep a weak reference to part(what it returns)."""
    made = Made()
    original = getattr(owner, name)

    def tracking(self: Any, *args: Any, **kwargs: Any) -> Any:
        out = original(self, *args, **kwargs)
        made.refs.append(weakref.ref(part(out)))
        return out

    monkeypatch.setattr(owner, name, tracking)
    return made
