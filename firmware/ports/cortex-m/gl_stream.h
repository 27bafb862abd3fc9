/**
 * @file gl_stream.h
 * @brief The replay and PIL stream of the Cortex-M image over semihosting files (main.c).
 *
 * in:  header {uint32 in_magic, count, block, watchdog_periods}, then `count` records of `in_size` bytes
 * out: header {uint32 out_magic, count, six words from the image's begin()}, then one record of `out_size`
 *      bytes per input record, written after each block
 *
 * Records are read up to `block` at a time (block 1 for a closed loop through FIFOs: gainlink.hil.loop.pil), never
 * more than the image's buffers hold (`max_block`). The record layouts are the law's (GL_LAW_RECORD_HEADER of gl_law.h, see main.c);
 * all little-endian.
 */
#ifndef GAINLINK_GL_STREAM_H
#define GAINLINK_GL_STREAM_H

#include <stdint.h>

/** @brief How one image answers the stream: its magics, record sizes, buffers and the two callbacks. */
typedef struct {
    uint32_t in_magic;  /**< expected first word of gl_in.bin */
    uint32_t out_magic; /**< first word of gl_out.bin */
    uint32_t in_size;   /**< bytes of one input record */
    uint32_t out_size;  /**< bytes of one output record */
    uint32_t max_block; /**< records that in_buf and out_buf hold */
    void *in_buf;       /**< max_block input records */
    void *out_buf;      /**< max_block output records */
    /**
     * Check the rest of the input header and start the loop; fill words 2..7 of the output header.
     * Returns GL_EXIT_OK or the image's exit status (semihost.h); nothing is written when it fails.
     */
    int (*begin)(const uint32_t in_hdr[4], uint32_t out_hdr[8]);
    /** One input record through the loop into its output record. */
    void (*record)(const void *in, void *out);
} gl_stream_t;

/**
 * @brief Replay the stream of the open file (or FIFO) `fin` into a new `gl_out.bin`.
 * @param[in] fin Semihosting handle of gl_in.bin.
 * @param[in] s The image's description.
 * @return GL_EXIT_OK, GL_EXIT_BAD_INPUT (bad magic or block 0), GL_EXIT_IO, or what begin() returned.
 */
int gl_stream_replay(int32_t fin, const gl_stream_t *s);

#endif /* GAINLINK_GL_STREAM_H */
