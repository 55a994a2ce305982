// rig_firmware: shaker-ident's reference firmware for a Teensy 4.0 / 4.1 (Arduino framework, Teensyduino).
//
// Samples three analog accelerometer channels (base, tip1, tip2 on A0, A1, A2) from a hardware timer
// (IntervalTimer, the i.MX RT1062's periodic interrupt timer) at RATE_MHZ, and streams frames v1 over
// the native USB serial port: one 24-byte data frame per sample (sequence counter, device time, three
// int16 counts, clipping flag, CRC) and a 36-byte status frame at boot and once a second (device id
// from the chip's unique id, a session id from the hardware random number generator, the rate, the
// firmware version). The frame bytes come from rigframe.c, the file the host's test suite compiles and
// checks against the Python decoder. Wiring and flashing: daq/firmware/README.md.
//
// Set RATE_MHZ to the config's daq.rate_hz (in millihertz); the host warns when they differ.

#include <Arduino.h>
#include <Entropy.h>
#include <IntervalTimer.h>

#include "rigframe.h"

// ---- what to adjust ----------------------------------------------------------------------------
static const uint32_t RATE_MHZ = 2000000;           // 2 kHz; = daq.rate_hz * 1000
static const uint8_t PINS[3] = {A0, A1, A2};        // base, tip1, tip2
static const bool INVERT[3] = {false, false, false}; // true behind an inverting conditioner stage
static const int ADC_BITS = 12;                      // the Teensy 4 ADC: 12 bits
static const int ADC_AVERAGING = 4;                  // hardware averaging of 4 conversions per read
static const int CLIP_MARGIN = 2;                    // counts from a rail that count as clipped
static const uint8_t FW_MAJOR = 1, FW_MINOR = 0;
// ------------------------------------------------------------------------------------------------

static const int32_t MID = 1 << (ADC_BITS - 1);      // mid-scale: the conditioner's bias, 0 counts
static const int32_t TOP = (1 << ADC_BITS) - 1;
static const uint32_t RING = 1024;                   // samples between the timer and the USB (0.5 s at 2 kHz)

struct Sample {
  uint64_t n;          // samples since boot: sequence number and device time follow from it
  int16_t counts[3];
  uint8_t flags;
};

static volatile Sample ring[RING];
static volatile uint32_t head = 0;  // written by the timer interrupt only
static volatile uint32_t tail = 0;  // written by loop() only
static volatile uint64_t taken = 0; // samples taken since boot (lost ones included)

static IntervalTimer timer;
static rigframe_stream stream;

// The timer interrupt: read the three channels, queue the sample. A full queue (the host stopped
// reading) loses the sample; its sequence number is skipped, so the host counts it as a drop.
static void sample_isr() {
  Sample s;
  s.n = taken;
  taken = taken + 1;
  s.flags = 0;
  for (int i = 0; i < 3; i++) {
    int32_t raw = analogRead(PINS[i]);
    if (raw <= CLIP_MARGIN || raw >= TOP - CLIP_MARGIN) {
      s.flags |= RIGFRAME_FLAG_CLIPPED;
    }
    int32_t c = raw - MID;
    s.counts[i] = (int16_t)(INVERT[i] ? -c : c);
  }
  uint32_t next = (head + 1) % RING;
  if (next != tail) {
    ring[head].n = s.n;
    for (int i = 0; i < 3; i++) {
      ring[head].counts[i] = s.counts[i];
    }
    ring[head].flags = s.flags;
    head = next;
  }
}

// FNV-1a over the chip's 64-bit unique id (OTP fuses CFG0, CFG1): a fixed id per unit.
static uint32_t device_id() {
  uint32_t words[2] = {HW_OCOTP_CFG0, HW_OCOTP_CFG1};
  uint32_t h = 2166136261u;
  for (int w = 0; w < 2; w++) {
    for (int b = 0; b < 4; b++) {
      h ^= (words[w] >> (8 * b)) & 0xFFu;
      h *= 16777619u;
    }
  }
  return h;
}

// 64 random bits from the hardware random number generator (TRNG), never 0.
static uint64_t session_id() {
  uint64_t s = 0;
  while (s == 0) {
    s = ((uint64_t)Entropy.random() << 32) | (uint64_t)Entropy.random();
  }
  return s;
}

void setup() {
  Serial.begin(115200);  // native USB: the number is ignored, the link runs at USB speed
  analogReadResolution(ADC_BITS);
  analogReadAveraging(ADC_AVERAGING);
  Entropy.Initialize();
  rigframe_identity id;
  id.session_id = session_id();
  id.device_id = device_id();
  id.rate_mhz = RATE_MHZ;
  id.fw_major = FW_MAJOR;
  id.fw_minor = FW_MINOR;
  rigframe_stream_init(&stream, &id);
  timer.priority(64);  // above USB (lower number = higher priority), so sampling never waits for it
  timer.begin(sample_isr, 1e9f / (float)RATE_MHZ);  // period in microseconds
}

void loop() {
  uint8_t buf[RIGFRAME_MAX_SAMPLE_BYTES];
  while (tail != head) {
    Sample s;
    noInterrupts();
    s.n = ring[tail].n;
    for (int i = 0; i < 3; i++) {
      s.counts[i] = ring[tail].counts[i];
    }
    s.flags = ring[tail].flags;
    interrupts();
    tail = (tail + 1) % RING;
    size_t len = rigframe_stream_sample(&stream, buf, (uint32_t)s.n, rigframe_time_us(s.n, RATE_MHZ), s.counts,
                                        s.flags);
    if (Serial.dtr()) {  // a program has the port open; writing may wait for the host, the ring absorbs it
      Serial.write(buf, len);
    }
    // else: nobody listens; the frame is not sent, and a host that opens the port later starts at a
    // status frame within a second
  }
}
