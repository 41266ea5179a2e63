"""Import errors and the import report: every repair or drop an importer makes is counted here, never silent.

The report ends up in ``trip.meta["import_report"]`` as a JSON dict::

    {"repairs": [{"what": "vehicle_speed", "action": "clipped to 0", "count": 12, "detail": "min -0.03 m/s"}, ...],
     "dropped": [{"what": "gnss_altitude.Altitude", "reason": "validity flag 0", "count": 41}, ...],
     "notes": ["..."]}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


class LogImportError(ValueError):
    """A log or mapping file cannot be imported; the message names the file, signal or channel at fault."""


@dataclass
class ImportReport:
    """Counted repairs and drops made while importing one log."""

    repairs: list[dict[str, Any]] = field(default_factory=list)
    dropped: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def repair(self, what: str, action: str, count: int, detail: str = "") -> None:
        """Record that `count` samples of `what` were changed by `action` (skipped when count is 0)."""
        if count:
            self.repairs.append({"what": what, "action": action, "count": int(count), "detail": detail})

    def drop(self, what: str, reason: str, count: int, detail: str = "") -> None:
        """Record that `count` samples/frames of `what` were removed for `reason` (skipped when count is 0)."""
        if count:
            self.dropped.append({"what": what, "reason": reason, "count": int(count), "detail": detail})

    def note(self, text: str) -> None:
        self.notes.append(text)

    def count(self, what: str | None = None) -> int:
        """Total number of repaired + dropped samples (of one signal/channel when `what` is given)."""
        rows = self.repairs + self.dropped
        return sum(r["count"] for r in rows if what is None or r["what"] == what)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> "ImportReport":
        """Rebuild a report from ``to_dict()`` output (e.g. to continue it after the mapping stage)."""
        return cls(list(raw.get("repairs", [])), list(raw.get("dropped", [])), list(raw.get("notes", [])))

    def to_dict(self) -> dict[str, Any]:
        return {"repairs": list(self.repairs), "dropped": list(self.dropped), "notes": list(self.notes),
                "n_repaired": sum(r["count"] for r in self.repairs),
                "n_dropped": sum(r["count"] for r in self.dropped)}

    def summary(self) -> str:
        """Human-readable lines, one per repair/drop."""
        lines = [f"repaired {r['count']} x {r['what']}: {r['action']}" + (f" ({r['detail']})" if r["detail"] else "")
                 for r in self.repairs]
        lines += [f"dropped {r['count']} x {r['what']}: {r['reason']}" + (f" ({r['detail']})" if r["detail"] else "")
                  for r in self.dropped]
        return "\n".join(lines + self.notes) if lines or self.notes else "no repairs, nothing dropped"
