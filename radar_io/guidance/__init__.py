"""Flight path guidance: reference paths and path deviation (radar-interface.md §6)."""

from __future__ import annotations

from .path import DEVIATION_COLUMNS, FRAME_COLUMNS, PathError, ReferencePath, add_deviation, load_path

__all__ = ["DEVIATION_COLUMNS", "FRAME_COLUMNS", "PathError", "ReferencePath", "add_deviation",
           "load_path"]
