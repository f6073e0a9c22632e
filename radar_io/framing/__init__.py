"""Framing: bytes → accepted frames, one core (:mod:`radar_io.framing.core`) for RDR1 and TLM1."""
