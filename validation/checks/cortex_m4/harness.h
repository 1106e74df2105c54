/*
 * gearsym's Cortex-M4F harness: what the driver needs from the platform. On the target
 * (GEARSYM_M4_TARGET, startup.c) the text goes out through semihosting and the SysTick counter
 * is read; on the host the driver prints to stdout and times nothing.
 */
#ifndef GEARSYM_M4_HARNESS_H
#define GEARSYM_M4_HARNESS_H

#include <stdint.h>

void gearsym_m4_put(const char *text);
#ifdef GEARSYM_M4_TARGET
void gearsym_m4_exit(int status);
void gearsym_m4_ticks_start(void);
uint32_t gearsym_m4_ticks(void);
/* SysTick ticks of a loop of exactly 2 instructions (subs, bne) per turn */
uint32_t gearsym_m4_calibration(uint32_t turns);
#endif

#endif /* GEARSYM_M4_HARNESS_H */
