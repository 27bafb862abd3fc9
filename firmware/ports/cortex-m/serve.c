/**
 * @file serve.c
 * @brief Option helpers of the UART servers (see serve.h).
 */
#include "serve.h"

#include <string.h>

#include "gl_uart.h"
#include "semihost.h"

int gl_serve_option(const char *arg, const char *key, const char **value)
{
    size_t n = strlen(key);
    if (strncmp(arg, key, n) == 0 && arg[n] == '=') {
        *value = &arg[n + 1u];
        return 1;
    }
    return 0;
}

int gl_serve_number(const char *text, uint32_t max, uint32_t *out)
{
    uint32_t base = 10u, v = 0u;
    if (text[0] == '0' && (text[1] == 'x' || text[1] == 'X')) {
        base = 16u;
        text += 2;
    }
    if (*text == '\0') {
        return -1;
    }
    for (; *text != '\0'; ++text) {
        char c = *text;
        uint32_t d;
        if (c >= '0' && c <= '9') {
            d = (uint32_t)(c - '0');
        } else if (base == 16u && c >= 'a' && c <= 'f') {
            d = (uint32_t)(c - 'a' + 10);
        } else if (base == 16u && c >= 'A' && c <= 'F') {
            d = (uint32_t)(c - 'A' + 10);
        } else {
            return -1;
        }
        if (d > max || v > (max - d) / base) {
            return -1;
        }
        v = v * base + d;
    }
    *out = v;
    return 0;
}

int gl_serve_refuse(const char *why)
{
    (void)gl_uart_write((const uint8_t *)"error: ", 7);
    (void)gl_uart_write((const uint8_t *)why, strlen(why));
    (void)gl_uart_write((const uint8_t *)"\n", 1);
    (void)gl_uart_flush(1000u);
    return GL_EXIT_BAD_INPUT;
}
