"""roadload.io: real logs in (CAN + DBC from MDF4/candump/BLF/ASC, CSV with a column map, OpenXC, BMW i3),
simulated trips out as CAN traffic, and road profiles from real logs.

Every loader reads its format into source signals and passes them through ONE declarative mapping layer
(``roadload.io.mapping``: source signal -> Trip channel, unit, scale/offset, resample rule); everything an
importer drops or repairs is counted in ``trip.meta["import_report"]``.
"""

from .frames import CanFrames, read_can_log, read_mf4, write_can_log
from .importer import import_log
from .mapping import Mapping, apply_mapping, load_mapping
from .report import ImportReport, LogImportError

__all__ = ["CanFrames", "ImportReport", "LogImportError", "Mapping", "apply_mapping", "import_log",
           "load_mapping", "read_can_log", "read_mf4", "write_can_log"]
