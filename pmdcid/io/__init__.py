"""Reading and writing logs and column mappings."""

from pmdcid.io.logs import Log, read_log, read_logs, write_log
from pmdcid.io.mapping import CANONICAL, ColumnMap, parse_mapping

__all__ = ["CANONICAL", "ColumnMap", "Log", "parse_mapping", "read_log", "read_logs", "write_log"]
