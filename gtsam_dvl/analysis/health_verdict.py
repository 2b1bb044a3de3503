"""The verdict of a health check (analysis/health.py after a run, analysis/live_health.py on a running estimator):
a status, the warnings that set it, notes that do not, and the figures behind them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# in order of severity: "warn" is an honest result that leans on its prior somewhere (weak geometry); --strict
# fails only on "degraded" and "failed"
STATUSES = ("ok", "warn", "degraded", "failed")


@dataclass
class Health:
    """Status of one run ("ok", "warn", "degraded", "failed"), the warnings that set it (each says what to do),
    notes that do not change it, and the figures behind them."""

    status: str = "ok"
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)

    def flag(self, severity: str, text: str) -> None:
        """A finding: "note" (status unchanged), "warn", "degraded" or "failed" (status at least that)."""
        if severity == "note":
            self.notes.append(text)
            return
        self.warnings.append(text)
        if STATUSES.index(severity) > STATUSES.index(self.status):
            self.status = severity

    def as_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "figures": self.figures,
        }

    def lines(self) -> list[str]:
        """One line per warning and note, for a console."""
        return (
            [f"health: {self.status}"]
            + [f"  warning: {w}" for w in self.warnings]
            + [f"  note: {n}" for n in self.notes]
        )
