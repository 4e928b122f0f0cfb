/* SPDX-License-Identifier: MIT */
/**
 * @file wire.h
 * The binary data-block header of the vafmd sample stream (protocol/wire.md).
 *
 * A data message is multipart: topic "data", this header (VAFM_WIRE_HEADER_SIZE bytes), then one raw
 * little-endian float64 array per channel, n_samples values each, in the channel order of the run's
 * "run.start" message. The header is defined by its byte layout, not by the C struct: encode and decode
 * go through explicit little-endian byte stores so the wire is the same on any host. The struct mirrors
 * the layout (static asserts below) so that a little-endian client may also memcpy it.
 */
#ifndef VAFM_WIRE_H
#define VAFM_WIRE_H
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#ifdef __cplusplus
extern "C" {
#endif

#define VAFM_WIRE_MAGIC 0x4D464156u    /**< bytes 'V','A','F','M' on the wire (u32 little-endian) */
#define VAFM_WIRE_PROTOCOL_VERSION 1u  /**< bumped on any incompatible change of the wire format */
#define VAFM_WIRE_HEADER_SIZE 72u      /**< bytes of the encoded header */

/** Header flags. */
enum vafm_wire_flag {
    VAFM_WIRE_FLAG_LATE = 1u,        /**< the block was released after its pacing deadline */
    VAFM_WIRE_FLAG_SEG_CHANGE = 2u,  /**< the segment changes inside this block (see "event" messages) */
    VAFM_WIRE_FLAG_LAST = 4u,        /**< last data block of the run */
    VAFM_WIRE_FLAG_FREE_RUN = 8u,    /**< produced in free-running mode (no pacing) */
    VAFM_WIRE_FLAG_CLIPPED = 16u,    /**< a vDeflection sample of the block saturated the ADC range (only
                                          with adc_bits > 0; deflection_m and force_N derive from it) */
};

/** Decoded data header; field order and sizes equal the wire layout. */
typedef struct vafm_wire_header {
    uint32_t magic;          /**< @0  VAFM_WIRE_MAGIC */
    uint16_t version;        /**< @4  VAFM_WIRE_PROTOCOL_VERSION */
    uint16_t header_size;    /**< @6  VAFM_WIRE_HEADER_SIZE (lets a later minor version append fields) */
    uint64_t seq;            /**< @8  data-message sequence number of this publisher, from 0, no gaps */
    uint64_t run_id;         /**< @16 run id assigned by the daemon (from 1) */
    uint64_t block_index;    /**< @24 index of this block in the run, from 0 */
    uint64_t first_sample;   /**< @32 index of the first sample of the block in the run */
    uint32_t n_samples;      /**< @40 samples per channel in this block */
    uint16_t n_channels;     /**< @44 number of channel frames that follow */
    uint16_t segment;        /**< @46 segment of the first sample (0 approach, 1 retract, 2 dwell, 3 tune) */
    double sample_rate_Hz;   /**< @48 output sample rate, Hz */
    int64_t t0_ns;           /**< @56 time of the first sample since the run start, ns (round(first/fs·1e9)) */
    uint32_t flags;          /**< @64 enum vafm_wire_flag, or-ed */
    union {
        uint32_t session;    /**< @68 the stream session (protocol/faults.md §4; 0 from daemons before 0.5) */
        uint32_t reserved;   /**< the same field by its name before the session (source compatibility) */
    };
} vafm_wire_header;

#if defined(__cplusplus)
#define VAFM_WIRE_SA static_assert
#else
#define VAFM_WIRE_SA _Static_assert
#endif
VAFM_WIRE_SA(sizeof(vafm_wire_header) == VAFM_WIRE_HEADER_SIZE, "wire header size");
VAFM_WIRE_SA(offsetof(vafm_wire_header, seq) == 8, "seq offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, run_id) == 16, "run_id offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, block_index) == 24, "block_index offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, first_sample) == 32, "first_sample offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, n_samples) == 40, "n_samples offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, n_channels) == 44, "n_channels offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, segment) == 46, "segment offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, sample_rate_Hz) == 48, "sample_rate_Hz offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, t0_ns) == 56, "t0_ns offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, flags) == 64, "flags offset");
VAFM_WIRE_SA(offsetof(vafm_wire_header, session) == 68, "session offset");
VAFM_WIRE_SA(sizeof(double) == 8, "IEEE-754 binary64 expected");
#undef VAFM_WIRE_SA

/* Byte-explicit little-endian stores and loads: independent of the host's byte order. */
static inline void vafm_wire_put_u16(unsigned char *b, uint16_t v)
{
    b[0] = (unsigned char)v;
    b[1] = (unsigned char)(v >> 8);
}
static inline void vafm_wire_put_u32(unsigned char *b, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        b[i] = (unsigned char)(v >> (8 * i));
}
static inline void vafm_wire_put_u64(unsigned char *b, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        b[i] = (unsigned char)(v >> (8 * i));
}
static inline uint16_t vafm_wire_get_u16(const unsigned char *b)
{
    return (uint16_t)(b[0] | (unsigned)b[1] << 8);
}
static inline uint32_t vafm_wire_get_u32(const unsigned char *b)
{
    uint32_t v = 0;
    for (int i = 3; i >= 0; i--)
        v = v << 8 | b[i];
    return v;
}
static inline uint64_t vafm_wire_get_u64(const unsigned char *b)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = v << 8 | b[i];
    return v;
}
/** A double travels as the little-endian bytes of its IEEE-754 bit pattern. */
static inline void vafm_wire_put_f64(unsigned char *b, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    vafm_wire_put_u64(b, v);
}
static inline double vafm_wire_get_f64(const unsigned char *b)
{
    uint64_t v = vafm_wire_get_u64(b);
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

/** Encode h into out[VAFM_WIRE_HEADER_SIZE]. */
static inline void vafm_wire_header_encode(const vafm_wire_header *h, unsigned char *out)
{
    vafm_wire_put_u32(out + 0, h->magic);
    vafm_wire_put_u16(out + 4, h->version);
    vafm_wire_put_u16(out + 6, h->header_size);
    vafm_wire_put_u64(out + 8, h->seq);
    vafm_wire_put_u64(out + 16, h->run_id);
    vafm_wire_put_u64(out + 24, h->block_index);
    vafm_wire_put_u64(out + 32, h->first_sample);
    vafm_wire_put_u32(out + 40, h->n_samples);
    vafm_wire_put_u16(out + 44, h->n_channels);
    vafm_wire_put_u16(out + 46, h->segment);
    vafm_wire_put_f64(out + 48, h->sample_rate_Hz);
    vafm_wire_put_u64(out + 56, (uint64_t)h->t0_ns);
    vafm_wire_put_u32(out + 64, h->flags);
    vafm_wire_put_u32(out + 68, h->session);
}

/** Decode len bytes into h. @return 0, or -1 if the buffer is short, the magic is wrong or the
 *  major protocol version differs (bytes past VAFM_WIRE_HEADER_SIZE, if header_size says so, are
 *  skipped by the caller). */
static inline int vafm_wire_header_decode(const unsigned char *in, size_t len, vafm_wire_header *h)
{
    if (len < VAFM_WIRE_HEADER_SIZE)
        return -1;
    h->magic = vafm_wire_get_u32(in + 0);
    h->version = vafm_wire_get_u16(in + 4);
    h->header_size = vafm_wire_get_u16(in + 6);
    h->seq = vafm_wire_get_u64(in + 8);
    h->run_id = vafm_wire_get_u64(in + 16);
    h->block_index = vafm_wire_get_u64(in + 24);
    h->first_sample = vafm_wire_get_u64(in + 32);
    h->n_samples = vafm_wire_get_u32(in + 40);
    h->n_channels = vafm_wire_get_u16(in + 44);
    h->segment = vafm_wire_get_u16(in + 46);
    h->sample_rate_Hz = vafm_wire_get_f64(in + 48);
    h->t0_ns = (int64_t)vafm_wire_get_u64(in + 56);
    h->flags = vafm_wire_get_u32(in + 64);
    h->session = vafm_wire_get_u32(in + 68);
    if (h->magic != VAFM_WIRE_MAGIC || h->version != VAFM_WIRE_PROTOCOL_VERSION ||
        h->header_size < VAFM_WIRE_HEADER_SIZE || h->header_size > len)
        return -1;
    return 0;
}

#ifdef __cplusplus
}
#endif
#endif
