"""argparse value types shared by the command-line modules: one clear message per bad value."""

from __future__ import annotations

import argparse
import math


def finite_float(text: str) -> float:
    """A finite number (no NaN or infinity)."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """A finite number above zero."""
    v = finite_float(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v
