/* rigframe: the serial frame format v1 of shaker-ident (README "Serial frame format"), encoder side.
 *
 * One small C99 file pair shared by the firmware (rig_firmware.ino) and the host test suite
 * (tests/test_firmware.py compiles rigframe.c with the system C compiler and checks every byte it
 * makes against the Python decoder, daq.protocol). No allocation, no globals, no I/O, no floating
 * point; byte order written explicitly, so the output is the same on any CPU.
 *
 * Data frame, 24 bytes: A5 5A, version 01, flags (bit 0 clipped, bit 7 = 0), sequence uint32,
 * device time uint64 [us], three int16 counts (base, tip1, tip2), CRC-16/CCITT-FALSE of bytes 0-21.
 * Status frame, 36 bytes: A5 5A, 01, type 80, counter uint32, device time uint64 [us], session id
 * uint64, device id uint32, rate uint32 [mHz], firmware major, minor, CRC of bytes 0-33.
 * All fields little-endian.
 */
#ifndef RIGFRAME_H
#define RIGFRAME_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RIGFRAME_VERSION 1u
#define RIGFRAME_DATA_LEN 24u
#define RIGFRAME_STATUS_LEN 36u
#define RIGFRAME_MAX_SAMPLE_BYTES (RIGFRAME_STATUS_LEN + RIGFRAME_DATA_LEN) /* what one sample can emit */
#define RIGFRAME_FLAG_CLIPPED 0x01u
#define RIGFRAME_TYPE_STATUS 0x80u
#define RIGFRAME_STATUS_PERIOD_US 1000000u /* one status frame per second of device time */

/* Who the device is: fixed per unit (device_id), drawn at every boot (session_id), and what it does. */
struct rigframe_identity {
    uint64_t session_id; /* random per boot, never 0 */
    uint32_t device_id;  /* fixed per unit */
    uint32_t rate_mhz;   /* sample rate in millihertz (2 kHz = 2000000) */
    uint8_t fw_major;
    uint8_t fw_minor;
};

/* When the next status frame is due. */
struct rigframe_stream {
    struct rigframe_identity id;
    uint32_t status_counter; /* status frames sent since boot */
    uint64_t next_status_us; /* device time at or after which the next status frame goes out */
    int started;             /* 0 until the boot status frame has been made */
};

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final XOR ("123456789" -> 0x29B1). */
uint16_t rigframe_crc16(const uint8_t *data, size_t len);

/* One data frame into out[24]; returns 24. Flag bits other than bit 0 are cleared. */
size_t rigframe_data(uint8_t *out, uint32_t seq, uint64_t t_us, const int16_t counts[3], uint8_t flags);

/* One status frame into out[36]; returns 36. */
size_t rigframe_status(uint8_t *out, const struct rigframe_identity *id, uint32_t counter, uint64_t t_us);

/* Device time of sample n since boot, microseconds, rounded down: n * 1e9 / rate_mhz without overflow
 * (the timer's clock: exact, no interrupt-latency jitter). */
uint64_t rigframe_time_us(uint64_t n, uint32_t rate_mhz);

void rigframe_stream_init(struct rigframe_stream *s, const struct rigframe_identity *id);

/* The bytes for one sample: a status frame first when one is due (at boot, then at the first sample at or
 * after each whole second of device time), then the data frame. out must hold RIGFRAME_MAX_SAMPLE_BYTES;
 * returns the number of bytes written (24 or 60). */
size_t rigframe_stream_sample(struct rigframe_stream *s, uint8_t *out, uint32_t seq, uint64_t t_us,
                              const int16_t counts[3], uint8_t flags);

#ifdef __cplusplus
}
#endif

#endif /* RIGFRAME_H */
