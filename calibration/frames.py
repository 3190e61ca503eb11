"""Binary frame format of the ADC stream, CRC-16, encoder, and a resynchronizing parser.

Frame (all multi-byte fields big-endian, as the ADS127L21 shifts data MSB first):

    offset  size  field
    0       2     sync 0xA5 0x5A
    2       2     sequence counter, uint16, +1 per frame, wraps at 65536
    4       1     n_ch, number of channels (1–8)
    5       3·n   samples, signed 24-bit two's complement, one per channel
    5+3n    2     CRC-16/CCITT-FALSE over bytes [2, 5+3n) (seq, n_ch, samples)

CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, xorout 0; check("123456789") = 0x29B1.
The parser scans for sync at every byte offset, so garbage, truncated and corrupted frames cost
only themselves: every complete candidate is CRC-checked (vectorized over candidates), accepted
frames never overlap, and a bad candidate is counted as corrupted unless it lies inside an
accepted frame (a sync pattern in sample data). Lost frames = gaps in the sequence counter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SYNC = b"\xa5\x5a"
MAX_CHANNELS = 8
SAMPLE_BYTES = 3                        # one sample word on the wire (tb_frame.h: TB_FRAME_LEN)
SAMPLE_BITS = 8 * SAMPLE_BYTES          # the word holds the ADC's code (the default sensor's width,
                                        # bridge.config.SensorConfig.bits; a test holds them equal)
SAMPLE_MIN, SAMPLE_MAX = -(1 << (SAMPLE_BITS - 1)), (1 << (SAMPLE_BITS - 1)) - 1


def _crc_table() -> np.ndarray:
    t = np.arange(256, dtype=np.uint32) << 8
    for _ in range(8):                       # 8 bit steps over all 256 entries at once
        t = np.where(t & 0x8000, (t << 1) ^ 0x1021, t << 1) & 0xFFFF
    return t.astype(np.uint16)


CRC_TABLE = _crc_table()


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (check value of b"123456789" is 0x29B1)."""
    crc = 0xFFFF
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ int(CRC_TABLE[((crc >> 8) ^ byte) & 0xFF])
    return crc


def crc16_rows(block: np.ndarray) -> np.ndarray:
    """CRC-16/CCITT-FALSE of each row of a (k, n) uint8 array (loop over n columns only)."""
    crc = np.full(block.shape[0], 0xFFFF, dtype=np.uint32)
    table = CRC_TABLE.astype(np.uint32)
    for j in range(block.shape[1]):
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ block[:, j]) & 0xFF]
    return crc.astype(np.uint16)


def frame_length(n_channels: int) -> int:
    """Bytes per frame: 2 sync + 2 seq + 1 n_ch + SAMPLE_BYTES·n + 2 CRC."""
    return 7 + SAMPLE_BYTES * n_channels


def encode_frames(seq, samples) -> bytes:
    """Frames for ``seq`` (k,) and ``samples`` (k, n_ch) int (clipped to the SAMPLE_BITS word),
    concatenated."""
    samples = np.atleast_2d(np.asarray(samples, dtype=np.int64))
    k, n = samples.shape
    if not 1 <= n <= MAX_CHANNELS:
        raise ValueError(f"n_ch must be 1..{MAX_CHANNELS}, got {n}")
    seq = np.asarray(seq, dtype=np.int64).reshape(k) & 0xFFFF
    v = np.clip(samples, SAMPLE_MIN, SAMPLE_MAX) & ((1 << SAMPLE_BITS) - 1)
    out = np.empty((k, frame_length(n)), dtype=np.uint8)
    out[:, 0], out[:, 1] = 0xA5, 0x5A
    out[:, 2], out[:, 3] = seq >> 8, seq & 0xFF
    out[:, 4] = n
    out[:, 5:5 + 3 * n:3] = v >> 16
    out[:, 6:6 + 3 * n:3] = (v >> 8) & 0xFF
    out[:, 7:7 + 3 * n:3] = v & 0xFF
    crc = crc16_rows(out[:, 2:5 + 3 * n])
    out[:, -2], out[:, -1] = crc >> 8, crc & 0xFF
    return out.tobytes()


@dataclass
class FrameStats:
    """Running counts of a stream."""

    frames: int = 0            # accepted (CRC-valid) frames
    corrupted: int = 0         # complete candidates whose CRC (or n_ch) failed
    lost: int = 0              # frames missing from the sequence (corrupted, dropped, truncated)
    garbage_bytes: int = 0     # bytes consumed that belonged to no accepted frame
    bytes: int = 0

    def as_dict(self) -> dict:
        return dict(frames=self.frames, corrupted=self.corrupted, lost=self.lost,
                    garbage_bytes=self.garbage_bytes, bytes=self.bytes)


class FrameParser:
    """Incremental parser: ``feed(bytes)`` → (seq (k,), samples (k, n_ch)) of new valid frames."""

    def __init__(self, n_channels: int = 1):
        if not 1 <= n_channels <= MAX_CHANNELS:
            raise ValueError(f"n_channels must be 1..{MAX_CHANNELS}")
        self.n = n_channels
        self.L = frame_length(n_channels)
        self.buf = bytearray()
        self.stats = FrameStats()
        self._last_seq: int | None = None

    def feed(self, data: bytes):
        self.buf += data
        self.stats.bytes += len(data)
        b = np.frombuffer(bytes(self.buf), dtype=np.uint8)
        size, L, n = b.size, self.L, self.n
        empty = (np.zeros(0, np.int64), np.zeros((0, n), np.int64))
        if size < 2:
            return empty
        cand = np.flatnonzero((b[:-1] == 0xA5) & (b[1:] == 0x5A))
        complete = cand[cand + L <= size]
        if complete.size:
            rows = b[complete[:, None] + np.arange(L)]
            ok = (rows[:, 4] == n) & (crc16_rows(rows[:, 2:L - 2]) ==
                                      ((rows[:, -2].astype(np.uint16) << 8) | rows[:, -1]))
        else:
            rows, ok = np.zeros((0, L), np.uint8), np.zeros(0, bool)
        starts = complete[ok]
        keep = np.ones(starts.size, bool)
        if starts.size > 1 and np.any(np.diff(starts) < L):    # rare: overlapping valid candidates
            last_end = -1
            for i, s in enumerate(starts):
                keep[i] = s >= last_end
                if keep[i]:
                    last_end = s + L
        starts, good = starts[keep], rows[ok][keep]
        bad = complete[~ok]
        if starts.size:
            j = np.searchsorted(starts, bad, side="right") - 1
            inside = (j >= 0) & (bad > starts[np.maximum(j, 0)]) & (bad < starts[np.maximum(j, 0)] + L)
            self.stats.corrupted += int(np.count_nonzero(~inside))
            end = int(starts[-1]) + L
        else:
            self.stats.corrupted += int(bad.size)
            end = 0
        pending = cand[(cand + L > size) & (cand >= end)]
        if pending.size:
            cut = int(pending[0])
        else:
            cut = size - 1 if b[-1] == 0xA5 else size
        cut = max(cut, end)
        self.stats.garbage_bytes += cut - L * int(starts.size)
        del self.buf[:cut]
        if not starts.size:
            return empty
        seq = (good[:, 2].astype(np.int64) << 8) | good[:, 3]
        raw = ((good[:, 5::3][:, :n].astype(np.int64) << 16) | (good[:, 6::3][:, :n].astype(np.int64) << 8)
               | good[:, 7::3][:, :n])
        samples = np.where(raw > SAMPLE_MAX, raw - (1 << SAMPLE_BITS), raw)
        prev = np.concatenate([[self._last_seq], seq[:-1]]) if self._last_seq is not None else seq[:-1]
        cur = seq if self._last_seq is not None else seq[1:]
        gaps = (cur - prev - 1) % 65536
        self.stats.lost += int(np.sum(np.where(gaps < 32768, gaps, 0)))
        self._last_seq = int(seq[-1])
        self.stats.frames += int(seq.size)
        return seq, samples


def parse_bytes(data: bytes, n_channels: int = 1):
    """Parse a whole capture: (seq, samples, stats)."""
    p = FrameParser(n_channels)
    seq, samples = p.feed(data)
    return seq, samples, p.stats
