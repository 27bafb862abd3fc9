/**
 * @file serve.h
 * @brief The image as a bus node on its console UART: MAVLink (gl_mav_node.h) or CAN through slcan
 *        (gl_can_node.h + gl_slcan.h). Selected at start (main.c); both run until the simulator stops.
 *
 * Options are `key=value` words. On a bad one the image writes `error: ...` on the UART and exits with
 * GL_EXIT_BAD_INPUT; otherwise it writes `ready PROTOCOL ...` and serves. The main loop drains the
 * receive ring into the node, lets it do its periodic work, and sleeps (WFI) until the next interrupt:
 * nothing in it waits for the UART.
 */
#ifndef GAINLINK_SERVE_H
#define GAINLINK_SERVE_H

#include <stdint.h>

/**
 * @brief MAVLink node on the UART, parameters persisted through flash_semihost.h.
 * @param[in] argc Option count.
 * @param[in] argv `sysid=1..255`, `compid=0..255` (defaults 1 and 1), `gains=artifact` (start on the compiled
 *                 set even when the flash holds a persisted one; the ready line's `gains=` names which runs).
 * @return Only on a bad option: GL_EXIT_BAD_INPUT.
 */
int gl_serve_mavlink(int argc, char *const argv[]);

/**
 * @brief CAN node behind an slcan adapter on the UART.
 * @param[in] argc Option count.
 * @param[in] argv `base=ID` (default 0x100), `encoding=float32|int16`; with int16 `meas=F:O/F:O/...`
 *                 (GL_P + GL_Q pairs) and `cmd=F:O/...` (GL_M pairs), F and O each the 16 hex digits of
 *                 an IEEE-754 double (exact; the same numbers as the DBC and the host app's --scale-*).
 * @return Only on a bad option: GL_EXIT_BAD_INPUT, or GL_EXIT_GAINS.
 */
int gl_serve_slcan(int argc, char *const argv[]);

/**
 * @brief The value of `key=value` if `arg` has that key.
 * @param[in]  arg   Word.
 * @param[in]  key   Key without '='.
 * @param[out] value Set to the text after '='.
 * @return 1 when it matches, else 0.
 */
int gl_serve_option(const char *arg, const char *key, const char **value);

/**
 * @brief A decimal or 0x-hex unsigned number no larger than `max`.
 * @param[in] text Text. @param[in] max Bound. @param[out] out Value.
 * @return 0, or -1 when malformed or too large.
 */
int gl_serve_number(const char *text, uint32_t max, uint32_t *out);

/**
 * @brief Write `error: WHY` on the UART, let it drain, and return GL_EXIT_BAD_INPUT.
 * @param[in] why Reason.
 * @return GL_EXIT_BAD_INPUT.
 */
int gl_serve_refuse(const char *why);

#endif /* GAINLINK_SERVE_H */
