"""python-can driver: open any interface by name and record its traffic to a log file."""

from __future__ import annotations

import os
import time
from typing import Any

from radar_io.errors import AirborneError


def open_bus(interface: str, channel: str, bitrate: int | None = None, **kwargs: Any) -> Any:
    """``can.Bus(interface=…, channel=…)``; errors become one-line AirborneErrors."""
    import can

    if bitrate is not None:
        kwargs["bitrate"] = bitrate
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except Exception as exc:  # python-can raises many types for a bad interface
        raise AirborneError(f"cannot open CAN interface {interface!r} channel {channel!r}: {exc}") from exc


class CanRecorder:
    """Writes every message received on ``bus`` to a python-can log (format by extension)."""

    def __init__(self, bus: Any, path: str | os.PathLike[str]) -> None:
        import can

        self.bus, self.path = bus, str(path)
        try:
            self.writer = can.Logger(self.path)
        except Exception as exc:  # unknown suffix, unwritable path, ...
            raise AirborneError(f"cannot write CAN log {self.path}: {exc}") from exc
        self.messages = 0

    def drain(self, timeout_s: float = 0.0) -> int:
        """Record the messages waiting (the first wait up to ``timeout_s``); returns how many."""
        import can

        n = 0
        try:
            msg = self.bus.recv(timeout=timeout_s)
            while msg is not None:
                self.writer.on_message_received(msg)
                n += 1
                msg = self.bus.recv(timeout=0.0)
        except can.CanError as exc:
            raise AirborneError(f"CAN receive failed: {exc}") from exc
        finally:
            self.messages += n
        return n

    def run(self, duration_s: float | None = None) -> int:
        """Record until ``duration_s`` has passed (None: until Ctrl-C); returns the message count."""
        end = None if duration_s is None else time.monotonic() + duration_s
        try:
            while end is None or time.monotonic() < end:
                left = 0.1 if end is None else max(0.0, min(0.1, end - time.monotonic()))
                self.drain(left)
        except KeyboardInterrupt:
            pass
        return self.messages

    def close(self) -> None:
        self.writer.stop()

    def __enter__(self) -> CanRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
