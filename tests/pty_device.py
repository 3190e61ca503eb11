"""A simulated serial device for the acquisition tests: two-channel frames (calibration.frames)
on a pseudo-terminal, a constant level plus AR(1) noise x_k = a x_{k−1} + e_k, e ~ N(0, σ²)
(a = 0: white noise), with junk bytes between blocks of frames."""

import contextlib
import os
import threading
import time

import numpy as np


class FrameDevice(threading.Thread):
    def __init__(self, fd, level, a=0.0, sigma=20.0, block=100):
        super().__init__(daemon=True)
        self.fd, self.level, self.a, self.sigma, self.block = fd, level, a, sigma, block
        self.stop, self.seq = threading.Event(), 0

    def run(self):
        from scipy.signal import lfilter          # here, not at import: scipy.signal costs ≈ 1 CPU-s

        from calibration.frames import encode_frames
        rng = np.random.default_rng(0)
        zi = np.zeros((1, 2))
        os.set_blocking(self.fd, False)
        pending = b""
        while not self.stop.is_set():
            if not pending:
                e = rng.normal(0.0, self.sigma, (self.block, 2))
                noise, zi = lfilter([1.0], [1.0, -self.a], e, axis=0, zi=zi)
                pending = b"\xa5junk" + encode_frames(np.arange(self.seq, self.seq + self.block),
                                                      np.round(self.level + noise))
                self.seq += self.block
            try:
                pending = pending[os.write(self.fd, pending):]    # partial writes continue
            except BlockingIOError:           # reader not keeping up: the pty buffer is full
                time.sleep(0.005)
                continue
            except OSError:
                return
            time.sleep(0.005)


@contextlib.contextmanager
def pty_device(level, **kw):
    """The device's tty path while it streams; stopped and closed afterwards."""
    master, slave = os.openpty()
    dev = FrameDevice(master, level, **kw)
    dev.start()
    try:
        yield os.ttyname(slave)
    finally:
        dev.stop.set()
        os.close(slave)                 # unblocks a writer stuck on a full pty buffer
        dev.join(2)
        os.close(master)
