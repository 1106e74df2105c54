/*
 * gearsym's Cortex-M4F drivers' output: one line of words and float bit patterns at a time,
 * printed through the harness (gearsym_m4_put) so that the host build and the emulated target
 * can be compared exactly; on the target, SysTick counts (instructions under -icount shift=0).
 * Shared by driver.c and control_driver.c; the including file defines GEARSYM_LINE_CHARS, the
 * longest line it prints, before including it.
 */
#ifndef GEARSYM_LINE_OUTPUT_H
#define GEARSYM_LINE_OUTPUT_H

#include <stdint.h>
#include <string.h>

#include "harness.h"

#ifndef GEARSYM_LINE_CHARS
#error "define GEARSYM_LINE_CHARS (the longest line printed) before including line_output.h"
#endif

static char line[GEARSYM_LINE_CHARS];
static size_t used_chars;

static void put_char(char c)
{
    if (used_chars + 1u < sizeof line) {
        line[used_chars++] = c;
        line[used_chars] = '\0';
    }
}

static void put_word(const char *w)
{
    while (*w != '\0') {
        put_char(*w++);
    }
}

static void put_hex(uint32_t v)
{
    static const char digits[] = "0123456789abcdef";
    put_char(' ');
    for (int shift = 28; shift >= 0; shift -= 4) {
        put_char(digits[(v >> (unsigned)shift) & 0xFu]);
    }
}

static void put_real(float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    put_hex(bits);
}

static void flush(void)
{
    put_char('\n');
    gearsym_m4_put(line);
    used_chars = 0u;
    line[0] = '\0';
}

#ifdef GEARSYM_M4_TARGET
#define TICKS() gearsym_m4_ticks()
#define ELAPSED(start, end) (((start) - (end)) & 0x00FFFFFFu)
static void report(const char *name, uint32_t value)
{
    put_word(name);
    put_hex(value);
    flush();
}
#endif

#endif /* GEARSYM_LINE_OUTPUT_H */
