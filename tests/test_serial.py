"""Serial acquisition: CRC check value, frame round trip, resync, loop:// and a pty fake device."""

import os
import threading
import time

import numpy as np
import pytest

from calibration.acquire import RawCapture, Reader, capture, guided_session, open_port, settled_mean
from userio.errors import InputError
from calibration.frames import (FrameParser, crc16_ccitt_false, crc16_rows, encode_frames,
                                frame_length, parse_bytes)


def test_crc16_ccitt_false_check_value():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    rows = np.frombuffer(b"123456789" * 2, np.uint8).reshape(2, 9)
    assert list(crc16_rows(rows)) == [0x29B1, 0x29B1]
    assert crc16_ccitt_false(b"") == 0xFFFF


def test_bitwise_crc_matches_table():
    def bitwise(data):                    # independent, bit-by-bit reference
        crc = 0xFFFF
        for byte in data:
            crc ^= byte << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        return crc
    rng = np.random.default_rng(1)
    for n in (1, 5, 31):
        data = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        assert crc16_ccitt_false(data) == bitwise(data)


def test_frame_layout_and_round_trip():
    fr = encode_frames([0x1234], [[-1, 2**23 - 1]])
    assert len(fr) == frame_length(2) == 13
    assert fr[:5] == bytes([0xA5, 0x5A, 0x12, 0x34, 2])
    assert fr[5:8] == b"\xff\xff\xff" and fr[8:11] == b"\x7f\xff\xff"
    assert int.from_bytes(fr[11:13], "big") == crc16_ccitt_false(fr[2:11])
    rng = np.random.default_rng(0)
    s = rng.integers(-2**23, 2**23, (500, 4))
    seq, out, st = parse_bytes(encode_frames(np.arange(500) + 65400, s), 4)   # wraps at 65536
    assert np.array_equal(out, s) and st.frames == 500 and st.lost == 0 and st.corrupted == 0
    assert np.array_equal(seq, (np.arange(500) + 65400) % 65536)


def _damaged_stream(rng, n=200, nch=2):
    s = rng.integers(-2**23, 2**23, (n, nch))
    L = frame_length(nch)
    fr = bytearray(encode_frames(np.arange(n), s))
    fr[10 * L + 6] ^= 0x40                              # corrupt frame 10
    data = bytes(rng.integers(0, 256, 53, dtype=np.uint8))   # leading garbage
    data += bytes(fr[:50 * L + 7]) + bytes(fr[51 * L:])     # frame 50 truncated
    data += b"\xa5\x5a\x00"                                 # trailing partial frame
    expected = np.setdiff1d(np.arange(n), [10, 50])
    return data, s, expected


def test_resync_after_garbage_corruption_and_truncation_any_chunking():
    rng = np.random.default_rng(3)
    data, s, expected = _damaged_stream(rng)
    for chunk in (1, 7, 64, len(data)):
        p = FrameParser(2)
        parts = [p.feed(data[i:i + chunk]) for i in range(0, len(data), chunk)]
        seq = np.concatenate([x[0] for x in parts])
        out = np.concatenate([x[1] for x in parts])
        assert np.array_equal(seq, expected), chunk
        assert np.array_equal(out, s[expected])
        assert p.stats.corrupted == 2 and p.stats.lost == 2
        assert p.stats.frames == expected.size


def test_sync_pattern_inside_samples_is_not_counted_corrupt():
    s = np.array([[0xA55A00 - 2**24], [0x00A55A], [5]])   # both hold the sync bytes
    seq, out, st = parse_bytes(encode_frames(np.arange(3), s), 1)
    assert np.array_equal(out[:, 0], s[:, 0]) and st.corrupted == 0


def test_loop_url_capture_writes_raw_before_parsing(tmp_path):
    port = open_port("loop://", 2_000_000, timeout_s=0.01)
    rng = np.random.default_rng(5)
    data, s, expected = _damaged_stream(rng, n=120, nch=2)
    port.write(data)
    raw = RawCapture(tmp_path / "cap.raw")
    reader = Reader(port, raw, FrameParser(2), chunk=100, keep=True)
    capture(reader, idle_timeout_s=0.2)
    assert raw.close().read_bytes() == data                      # every byte, in order
    assert not (tmp_path / "cap.raw.part").exists()
    assert np.array_equal(np.concatenate(reader.seq_log), expected)
    assert reader.parser.stats.corrupted == 2


def test_raw_bytes_survive_a_parser_crash(tmp_path):
    port = open_port("loop://", timeout_s=0.01)
    port.write(encode_frames(np.arange(5), np.zeros((5, 1))))

    class Boom(FrameParser):
        def feed(self, data):
            raise RuntimeError("parser bug")
    raw = RawCapture(tmp_path / "x.raw")
    with pytest.raises(RuntimeError):
        capture(Reader(port, raw, Boom(1)), idle_timeout_s=0.1)
    raw.abort()
    assert len((tmp_path / "x.raw.part").read_bytes()) == 5 * frame_length(1)
    assert not (tmp_path / "x.raw").exists()


def test_raw_capture_refuses_to_overwrite(tmp_path):
    (tmp_path / "a.raw").write_bytes(b"keep")
    with pytest.raises(InputError, match="exists"):
        RawCapture(tmp_path / "a.raw")
    assert (tmp_path / "a.raw").read_bytes() == b"keep"


class FakeDevice(threading.Thread):
    """Writes frames to a pty master: a level per 'mass', noise, garbage and bad frames."""

    def __init__(self, fd, levels, n_per_level, *, rate_hz=20000, seed=0):
        super().__init__(daemon=True)
        self.fd, self.levels, self.n = fd, levels, n_per_level
        self.rate, self.rng = rate_hz, np.random.default_rng(seed)
        self.level = levels[0]
        self.stop = threading.Event()
        self.seq = 0

    def run(self):
        block = 200
        while not self.stop.is_set():
            x = self.level + self.rng.normal(0, 30, (block, 1))
            fr = bytearray(encode_frames(np.arange(self.seq, self.seq + block), np.round(x)))
            L = frame_length(1)
            fr[3 * L + 5] ^= 0xFF                          # one corrupted frame per block
            fr = bytes(fr[:100 * L + 4]) + bytes(fr[101 * L:])   # and one truncated
            self.seq += block
            try:
                os.write(self.fd, b"\x00garbage" + fr)
            except OSError:
                return
            time.sleep(block / self.rate)


def test_pty_fake_device_guided_session(tmp_path):
    master, slave = os.openpty()
    levels = {0.0: 1000.0, 100.0: 51000.0, 200.0: 101000.0}
    dev = FakeDevice(master, list(levels.values()), 0)
    dev.start()
    try:
        port = open_port(os.ttyname(slave), 2_000_000, timeout_s=0.02)
        reader = Reader(port, RawCapture(tmp_path / "s.raw"), FrameParser(1))
        answers = iter(["", "", "200"])          # scripted operator: Enter, Enter, actual mass
        planned = iter([0.0, 100.0, 200.0])

        def prompt(msg):
            dev.level = levels[next(planned)]      # the operator places the weight
            return next(answers)
        rows = guided_session(reader, [0, 100, 150], settle_samples=400, window_samples=800,
                              prompt=prompt, out=open(os.devnull, "w"))
        reader.raw.close()
    finally:
        dev.stop.set()
        dev.join(2)
        os.close(master)
        os.close(slave)
    assert [r["mass_g"] for r in rows] == [0.0, 100.0, 200.0]
    for r, lv in zip(rows, levels.values()):
        assert r["settled"] == 1
        assert abs(r["reading"] - lv) < 5 * 30 / np.sqrt(800)
    st = reader.parser.stats
    assert st.corrupted > 0 and st.lost >= st.corrupted
    assert (tmp_path / "s.raw").stat().st_size == st.bytes


def test_settled_window_detects_a_ramp():
    rng = np.random.default_rng(0)
    flat = 100 + rng.normal(0, 1, 1000)
    assert settled_mean(flat)[0]
    assert not settled_mean(flat + np.linspace(0, 5, 1000))[0]
    assert settled_mean(flat + np.linspace(0, 5, 1000), tol=10)[0]
