"""The Arduino sketch's frame code (tb_frame.h), compiled on the host, emits what the parser expects."""

import shutil
import subprocess

import numpy as np
import pytest

from calibration.frames import encode_frames, parse_bytes
from torquebench.io import REPO_ROOT

HEADER = REPO_ROOT / "calibration" / "firmware" / "torquebench_adc" / "tb_frame.h"

HARNESS = r"""
#include <stdio.h>
#include "tb_frame.h"
int main(void) {
  const uint8_t check[] = "123456789";
  printf("%04X\n", tb_crc16_ccitt_false(check, 9));
  int32_t s[3];
  uint8_t buf[TB_FRAME_LEN(3)];
  for (int k = 0; k < 300; ++k) {
    s[0] = k * 40001 - 6000000; s[1] = -k * 977; s[2] = (k % 2) ? 9000000 : -9000000;  /* clipped */
    size_t n = tb_build_frame(buf, (uint16_t)(65500 + k), s, 3);
    for (size_t i = 0; i < n; ++i) printf("%02X", buf[i]);
  }
  printf("\n%ld\n", (long)tb_sign_extend24(0xFFFFFEu));
  return 0;
}
"""


@pytest.mark.skipif(shutil.which("g++") is None, reason="no host C++ compiler")
def test_firmware_frames_match_python_encoder(tmp_path):
    (tmp_path / "h.cpp").write_text(HARNESS)
    exe = tmp_path / "h"
    subprocess.run(["g++", "-std=c++11", "-Wall", "-Werror", "-I", str(HEADER.parent),
                    str(tmp_path / "h.cpp"), "-o", str(exe)], check=True)
    crc, frames_hex, sx = subprocess.run([str(exe)], capture_output=True, text=True,
                                         check=True).stdout.split()
    assert crc == "29B1" and int(sx) == -2
    k = np.arange(300)
    s = np.column_stack([k * 40001 - 6000000, -k * 977, np.where(k % 2, 9000000, -9000000)])
    data = bytes.fromhex(frames_hex)
    assert data == encode_frames(65500 + k, s)
    seq, out, st = parse_bytes(data, 3)
    assert st.frames == 300 and st.lost == 0 and np.array_equal(seq, (65500 + k) % 65536)
    assert np.array_equal(out[:, 2], np.where(k % 2, 2**23 - 1, -(2**23)))


ARDUINO_STUBS = r"""
#include <stdint.h>
#include <stddef.h>
#define HIGH 1
#define LOW 0
#define OUTPUT 1
#define INPUT 0
#define LED_BUILTIN 13
#define MSBFIRST 1
#define SPI_MODE1 1
struct SPISettings { SPISettings(uint32_t, uint8_t, uint8_t) {} };
struct SPIClass { void begin() {} void beginTransaction(const SPISettings&) {} void endTransaction() {}
                  uint8_t transfer(uint8_t) { return 0xA5; } } SPI;
struct SerialClass { void begin(unsigned long) {} size_t write(const uint8_t*, size_t n) { return n; }
                     explicit operator bool() const { return true; } } SerialUSB, Serial;
inline void pinMode(int, int) {}
inline void digitalWrite(int, int) {}
inline int digitalRead(int) { return 0; }
inline void delay(unsigned long) {}
inline void delayMicroseconds(unsigned int) {}
"""


@pytest.mark.skipif(shutil.which("g++") is None, reason="no host C++ compiler")
@pytest.mark.parametrize("simulate", ["0", "1"])
def test_sketch_compiles_against_arduino_stubs(tmp_path, simulate):
    """Syntax/type check of the .ino with minimal Arduino stubs (not a substitute for arduino-cli)."""
    (tmp_path / "SPI.h").write_text(ARDUINO_STUBS)
    ino = (HEADER.parent / "torquebench_adc.ino").read_text().replace(
        "#define SIMULATE 0", f"#define SIMULATE {simulate}")
    (tmp_path / "sketch.cpp").write_text(ino + "\nint main() { setup(); for (int i = 0; i < 3; ++i) loop(); }\n")
    subprocess.run(["g++", "-std=c++11", "-Wall", "-Werror", "-I", str(tmp_path), "-I",
                    str(HEADER.parent), str(tmp_path / "sketch.cpp"), "-o", str(tmp_path / "s")],
                   check=True)
    subprocess.run([str(tmp_path / "s")], check=True, timeout=10)
