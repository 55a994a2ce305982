/* rigframe: frame encoder of shaker-ident's serial format v1 (see rigframe.h). */
#include "rigframe.h"

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    int i;
    for (i = 0; i < 4; i++) {
        p[i] = (uint8_t)((v >> (8 * i)) & 0xFFu);
    }
}

static void put_u64(uint8_t *p, uint64_t v)
{
    int i;
    for (i = 0; i < 8; i++) {
        p[i] = (uint8_t)((v >> (8 * i)) & 0xFFu);
    }
}

uint16_t rigframe_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    size_t i;
    int bit;
    for (i = 0; i < len; i++) {
        crc = (uint16_t)(crc ^ ((uint16_t)data[i] << 8));
        for (bit = 0; bit < 8; bit++) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

static void header(uint8_t *out, uint8_t type_or_flags)
{
    out[0] = 0xA5u;
    out[1] = 0x5Au;
    out[2] = (uint8_t)RIGFRAME_VERSION;
    out[3] = type_or_flags;
}

size_t rigframe_data(uint8_t *out, uint32_t seq, uint64_t t_us, const int16_t counts[3], uint8_t flags)
{
    int i;
    header(out, (uint8_t)(flags & RIGFRAME_FLAG_CLIPPED));
    put_u32(out + 4, seq);
    put_u64(out + 8, t_us);
    for (i = 0; i < 3; i++) {
        put_u16(out + 16 + 2 * i, (uint16_t)counts[i]); /* two's complement, as int16 little-endian */
    }
    put_u16(out + 22, rigframe_crc16(out, 22));
    return RIGFRAME_DATA_LEN;
}

size_t rigframe_status(uint8_t *out, const struct rigframe_identity *id, uint32_t counter, uint64_t t_us)
{
    header(out, (uint8_t)RIGFRAME_TYPE_STATUS);
    put_u32(out + 4, counter);
    put_u64(out + 8, t_us);
    put_u64(out + 16, id->session_id);
    put_u32(out + 24, id->device_id);
    put_u32(out + 28, id->rate_mhz);
    out[32] = id->fw_major;
    out[33] = id->fw_minor;
    put_u16(out + 34, rigframe_crc16(out, 34));
    return RIGFRAME_STATUS_LEN;
}

uint64_t rigframe_time_us(uint64_t n, uint32_t rate_mhz)
{
    /* t = n * 1e9 / rate_mhz [us], split so nothing overflows: every rate_mhz samples last exactly 1e9 us */
    uint64_t whole = n / rate_mhz;
    uint64_t rest = n % rate_mhz; /* < 2^32, so rest * 1e9 < 2^62 */
    return whole * 1000000000u + (rest * 1000000000u) / rate_mhz;
}

void rigframe_stream_init(struct rigframe_stream *s, const struct rigframe_identity *id)
{
    s->id = *id;
    s->status_counter = 0;
    s->next_status_us = 0;
    s->started = 0;
}

size_t rigframe_stream_sample(struct rigframe_stream *s, uint8_t *out, uint32_t seq, uint64_t t_us,
                              const int16_t counts[3], uint8_t flags)
{
    size_t n = 0;
    if (!s->started || t_us >= s->next_status_us) {
        n += rigframe_status(out, &s->id, s->status_counter, t_us);
        s->status_counter++;
        if (!s->started) {
            s->next_status_us = t_us - t_us % RIGFRAME_STATUS_PERIOD_US;
            s->started = 1;
        }
        while (s->next_status_us <= t_us) { /* the next whole second of device time */
            s->next_status_us += RIGFRAME_STATUS_PERIOD_US;
        }
    }
    n += rigframe_data(out + n, seq, t_us, counts, flags);
    return n;
}
