// torquebench ADC stream frame (see calibration/frames.py; keep the two in step).
//
//   offset  size  field
//   0       2     sync 0xA5 0x5A
//   2       2     sequence counter, uint16 big-endian, +1 per frame, wraps
//   4       1     n_ch (1..8)
//   5       3*n   samples, signed 24-bit two's complement, big-endian (ADC order, MSB first)
//   5+3n    2     CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0)
//                 over bytes [2, 5+3n), big-endian.  check("123456789") == 0x29B1
//
// Plain C++ with <stdint.h> only, so the host test suite compiles it with g++ and compares
// the bytes with the Python encoder (tests/test_serial_firmware.py).
#ifndef TB_FRAME_H
#define TB_FRAME_H

#include <stddef.h>
#include <stdint.h>

#define TB_SYNC0 0xA5
#define TB_SYNC1 0x5A
#define TB_MAX_CH 8
#define TB_FRAME_LEN(n) (7 + 3 * (n))

static inline uint16_t tb_crc16_ccitt_false(const uint8_t *data, size_t len) {
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < len; ++i) {
    crc ^= (uint16_t)data[i] << 8;
    for (uint8_t b = 0; b < 8; ++b) {
      crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
  }
  return crc;
}

// Write one frame into out[TB_FRAME_LEN(n_ch)]; samples are clipped to the 24-bit range.
// Returns the number of bytes written (0 if n_ch is out of range).
static inline size_t tb_build_frame(uint8_t *out, uint16_t seq, const int32_t *samples,
                                    uint8_t n_ch) {
  if (n_ch < 1 || n_ch > TB_MAX_CH) return 0;
  out[0] = TB_SYNC0;
  out[1] = TB_SYNC1;
  out[2] = (uint8_t)(seq >> 8);
  out[3] = (uint8_t)(seq & 0xFF);
  out[4] = n_ch;
  for (uint8_t c = 0; c < n_ch; ++c) {
    int32_t v = samples[c];
    if (v > 8388607) v = 8388607;
    if (v < -8388608) v = -8388608;
    uint32_t u = (uint32_t)v & 0xFFFFFFu;
    out[5 + 3 * c] = (uint8_t)(u >> 16);
    out[6 + 3 * c] = (uint8_t)(u >> 8);
    out[7 + 3 * c] = (uint8_t)u;
  }
  size_t n = 5 + 3 * (size_t)n_ch;
  uint16_t crc = tb_crc16_ccitt_false(out + 2, n - 2);
  out[n] = (uint8_t)(crc >> 8);
  out[n + 1] = (uint8_t)(crc & 0xFF);
  return n + 2;
}

// Sign-extend a 24-bit two's-complement word read MSB first from the ADC.
static inline int32_t tb_sign_extend24(uint32_t raw) {
  raw &= 0xFFFFFFu;
  return (raw & 0x800000u) ? (int32_t)(raw | 0xFF000000u) : (int32_t)raw;
}

#endif  // TB_FRAME_H
