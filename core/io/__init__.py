"""roadload.io: real logs in (CAN + DBC from MDF4/candump/BLF/ASC, CSV with a column map, OpenXC, BMW i3),
simulated trips out as CAN traffic, and road profiles from real logs.

Every loader reads its format into source signals and passes them through ONE declarative mapping layer
(``roadload.io.mapping``: source signal -> Trip channel, unit, scale/offset, resample rule); everything an
importer drops or repairs is counted in ``trip.meta["import_report"]``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .frames import CanFrames, read_can_log, read_mf4, write_can_log
    from .importer import import_log
    from .mapping import Mapping, apply_mapping, load_mapping
    from .report import ImportReport, LogImportError

# names load with their module on first use (PEP 562): importing roadload.io.mapping to check a mapping file does
# not import the loaders, their road-profile helpers and scipy
_LAZY = {"CanFrames": ".frames", "read_can_log": ".frames", "read_mf4": ".frames", "write_can_log": ".frames",
         "import_log": ".importer", "Mapping": ".mapping", "apply_mapping": ".mapping", "load_mapping": ".mapping",
         "ImportReport": ".report", "LogImportError": ".report"}
__all__ = ["CanFrames", "ImportReport", "LogImportError", "Mapping", "apply_mapping", "import_log",
           "load_mapping", "read_can_log", "read_mf4", "write_can_log"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'roadload.io' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
