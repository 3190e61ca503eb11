// torquebench_adc: Arduino Due forwarding 24-bit ADC samples (ADS127L21, one per torque sensor)
// to the host as framed binary packets (format in tb_frame.h; parser in calibration/frames.py).
//
// Wiring (one ADS127L21 per channel, shared SCLK/MOSI/MISO on the Due's SPI header, START and
// the modulator clock shared so all converters sample together; DRDY of channel 0 paces us):
//   CS of channel c -> CS_PINS[c], DRDY of channel 0 -> DRDY_PIN.
// Host side:  torquebench acquire --port /dev/ttyACM0 --channels 2 --out run.raw
// The native USB port (SerialUSB) ignores the baud rate and sustains the 3-4 kSps x n_ch x 3 B;
// on the programming port use Serial at 2 000 000 baud (the paper's setup).
// SIMULATE 1 emits a synthetic staircase without any ADC attached (bring-up of the host side).

#include <SPI.h>
#include "tb_frame.h"

#define SIMULATE 0
#define USE_NATIVE_USB 1

static const uint8_t N_CH = 2;
static const uint8_t CS_PINS[N_CH] = {10, 4};
static const uint8_t DRDY_PIN = 9;
// ADS127L21 SPI: mode 1 (CPOL 0, CPHA 1), MSB first; check the datasheet of your ADC/board.
static const SPISettings ADC_SPI(20000000, MSBFIRST, SPI_MODE1);

#if USE_NATIVE_USB
#define HOST SerialUSB
#else
#define HOST Serial
#endif

static uint16_t seq = 0;
static uint8_t frame[TB_FRAME_LEN(TB_MAX_CH)];

int32_t readAdc(uint8_t cs) {
  SPI.beginTransaction(ADC_SPI);
  digitalWrite(cs, LOW);
  uint32_t raw = (uint32_t)SPI.transfer(0) << 16;
  raw |= (uint32_t)SPI.transfer(0) << 8;
  raw |= (uint32_t)SPI.transfer(0);
  digitalWrite(cs, HIGH);
  SPI.endTransaction();
  return tb_sign_extend24(raw);
}

void setup() {
  pinMode(LED_BUILTIN, OUTPUT);
  // Self-test of the CRC against the published check value; blink forever if it fails.
  const uint8_t check[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  if (tb_crc16_ccitt_false(check, sizeof(check)) != 0x29B1) {
    for (;;) { digitalWrite(LED_BUILTIN, !digitalRead(LED_BUILTIN)); delay(100); }
  }
  for (uint8_t c = 0; c < N_CH; ++c) { pinMode(CS_PINS[c], OUTPUT); digitalWrite(CS_PINS[c], HIGH); }
  pinMode(DRDY_PIN, INPUT);
  SPI.begin();
  HOST.begin(2000000);
  while (!HOST) {}
}

void loop() {
  int32_t samples[N_CH];
#if SIMULATE
  static uint32_t n = 0;
  delayMicroseconds(250);                          // ~4 kSps
  for (uint8_t c = 0; c < N_CH; ++c) samples[c] = (int32_t)((n / 4000) % 8) * 100000 + (int32_t)(n % 7) - 3;
  ++n;
#else
  while (digitalRead(DRDY_PIN) == HIGH) {}         // DRDY falls when a conversion is ready
  for (uint8_t c = 0; c < N_CH; ++c) samples[c] = readAdc(CS_PINS[c]);
#endif
  size_t len = tb_build_frame(frame, seq++, samples, N_CH);
  HOST.write(frame, len);
}
