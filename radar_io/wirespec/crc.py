"""CRC-16 from the spec's parameters (non-reflected, Rocksoft model).

Per frame we use the standard library's ``binascii.crc_hqx`` (CRC-16/CCITT,
poly 0x1021, any init) when the spec asks for that polynomial; the batch path
uses 65536-entry tables derived from the same byte-wise definition:
:func:`word_table` advances the register by one 16-bit word, and
:func:`position_tables` give, for a message of fixed length, each word
position's own contribution, since a CRC without reflection is affine in the
message bits: ``crc = c0 ^ T_1[w_1] ^ T_2[w_2] ^ … ^ T_n[w_n]`` (independent
lookups, no register carried from word to word).
"""

from __future__ import annotations

import binascii
from collections.abc import Callable
from functools import lru_cache

import numpy as np

from radar_io.wirespec.frame import CrcSpec


def _byte_table(poly: int) -> list[int]:
    table = []
    for b in range(256):
        r = b << 8
        for _ in range(8):
            r = ((r << 1) ^ poly) if r & 0x8000 else (r << 1)
        table.append(r & 0xFFFF)
    return table


def crc_function(c: CrcSpec) -> Callable[[bytes], int]:
    """``f(data) -> int``: the CRC of ``data`` as the spec defines it."""
    init, xor_out = c.init, c.xor_out
    if c.poly == 0x1021:
        if xor_out == 0:
            return lambda data: binascii.crc_hqx(data, init)
        return lambda data: binascii.crc_hqx(data, init) ^ xor_out
    table = _byte_table(c.poly)

    def crc(data: bytes) -> int:
        r = init
        for b in data:
            r = ((r << 8) & 0xFFFF) ^ table[(r >> 8) ^ b]
        return r ^ xor_out

    return crc


@lru_cache(maxsize=8)
def word_table(poly: int) -> np.ndarray:
    """``T[v]``: the register after feeding the 16-bit word ``v`` (big-endian) to a zero register.

    For a non-reflected 16-bit CRC, feeding word ``w`` to register ``r`` gives
    ``T[r ^ w]``; the whole table is the byte-wise recurrence applied twice.
    """
    t8 = np.array(_byte_table(poly), dtype=np.uint32)
    v = np.arange(65536, dtype=np.uint32)
    r1 = t8[v >> 8]                                  # after the high byte
    r2 = ((r1 << 8) & 0xFFFF) ^ t8[(r1 >> 8) ^ (v & 0xFF)]
    return r2.astype(np.uint16)


@lru_cache(maxsize=8)
def position_tables(poly: int, init: int, xor_out: int, first_word: int, nwords: int
                    ) -> tuple[int, tuple[np.ndarray, ...]]:
    """``(c0, (T_1 … T_{nwords-1}))`` for messages of ``nwords`` 16-bit words whose word 0 is
    always ``first_word`` (the sync word): ``crc = c0 ^ T_1[w_1] ^ … ^ T_{n-1}[w_{n-1}]``.

    ``T_k[v]`` is the register contribution of word ``v`` at position ``k``: the word
    table advanced through the ``nwords - 1 - k`` words that follow (zeros add nothing
    but shifts). ``c0`` is the CRC of the message holding only ``first_word`` at
    position 0 and zeros elsewhere, ``init`` and ``xor_out`` included.
    """
    t = word_table(poly)
    tables: list[np.ndarray] = []
    cur = t.copy()
    for _ in range(1, nwords):       # T_{n-1} = t, T_{n-2} = t advanced once, ...
        tables.append(cur)
        cur = t.take(cur)
    tables.reverse()
    reg = init
    for v in (first_word, *([0] * (nwords - 1))):
        reg = int(t[reg ^ v])
    return reg ^ xor_out, tuple(tables)
