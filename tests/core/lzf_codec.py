"""LZF for tests and benchmarks: a small greedy compressor, liblzf's decoder written byte by byte
(the reference the vectorised :func:`nurbs_core.io.pcd.lzf_decompress` is checked and timed
against) and random valid streams exercising every token kind."""

from __future__ import annotations

import numpy as np


def lzf_compress(data: bytes) -> bytes:
    """A small greedy LZF compressor (liblzf's stream format: literal runs of up to 32 bytes,
    back references of 3 to 264 bytes up to 8192 back)."""
    out, table, i, literal = bytearray(), {}, 0, 0

    def literals(stop):
        for start in range(literal, stop, 32):
            chunk = data[start: min(start + 32, stop)]
            out.append(len(chunk) - 1)
            out.extend(chunk)

    while i < len(data) - 2:
        key = data[i: i + 3]
        reference = table.get(key)
        table[key] = i
        if reference is not None and i - reference <= 8192:
            length, limit = 3, min(264, len(data) - i)
            while length < limit and data[reference + length] == data[i + length]:
                length += 1
            literals(i)
            distance = i - reference - 1
            if length < 9:
                out.append(((length - 2) << 5) | (distance >> 8))
            else:
                out += bytes([(7 << 5) | (distance >> 8), length - 9])
            out.append(distance & 255)
            i += length
            literal = i
        else:
            i += 1
    literals(len(data))
    return bytes(out)


def lzf_reference(data: bytes, size: int) -> bytes:
    """liblzf's decoder, byte by byte (for comparison)."""
    out, position = bytearray(), 0
    while position < len(data):
        control = data[position]
        position += 1
        if control < 32:
            out += data[position: position + control + 1]
            position += control + 1
            continue
        length = control >> 5
        if length == 7:
            length += data[position]
            position += 1
        reference = len(out) - ((control & 31) << 8) - data[position] - 1
        position += 1
        for _ in range(length + 2):
            out.append(out[reference])
            reference += 1
    assert len(out) == size
    return bytes(out)


def random_lzf_stream(rng, tokens: int) -> tuple[bytes, int]:
    out, size = bytearray(), 0
    for _ in range(tokens):
        if size == 0 or rng.random() < 0.3:
            n = int(rng.integers(1, 33))
            out.append(n - 1)
            out += rng.integers(0, 4, n, dtype=np.uint8).tobytes()
            size += n
            continue
        distance = int(rng.integers(1, min(size, 8192) + 1))
        length = int(rng.integers(3, 265 if rng.random() < 0.5 else 9))
        if length < 9:
            out.append(((length - 2) << 5) | ((distance - 1) >> 8))
        else:
            out += bytes([(7 << 5) | ((distance - 1) >> 8), length - 9])
        out.append((distance - 1) & 255)
        size += length
    return bytes(out), size
