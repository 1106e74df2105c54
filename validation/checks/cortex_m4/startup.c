/*
 * Bare-metal start-up of gearsym's Cortex-M4F harness (QEMU mps2-an386): vector table, reset
 * handler (FPU on through CPACR, .data copied, .bss zeroed, main called), semihosting output
 * (SYS_WRITE0, SYS_EXIT through bkpt 0xab) and the SysTick counter used to count instructions
 * under `qemu-system-arm -icount shift=0`. No heap, no newlib start-up files.
 */
#include <stdint.h>

#include "harness.h"

extern uint32_t __data_load[], __data_start[], __data_end[], __bss_start[], __bss_end[];
extern uint32_t __stack_top[];
int main(void);
void gearsym_m4_reset(void);
void gearsym_m4_fault(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)

#define SYS_WRITE0 0x04u
#define SYS_EXIT 0x18u
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u
#define ADP_STOPPED_RUN_TIME_ERROR 0x20023u

typedef void (*vector)(void);

__attribute__((section(".vectors"), used)) static const vector vectors[16] = {
    (vector)(uintptr_t)__stack_top, /* initial stack pointer */
    gearsym_m4_reset,               /* reset */
    gearsym_m4_fault,               /* NMI */
    gearsym_m4_fault,               /* hard fault */
    gearsym_m4_fault,               /* memory management fault */
    gearsym_m4_fault,               /* bus fault */
    gearsym_m4_fault,               /* usage fault */
    0, 0, 0, 0,                     /* reserved */
    gearsym_m4_fault,               /* SVCall */
    gearsym_m4_fault,               /* debug monitor */
    0,                              /* reserved */
    gearsym_m4_fault,               /* PendSV */
    gearsym_m4_fault,               /* SysTick (its interrupt stays disabled) */
};

static uint32_t semihost(uint32_t op, const void *arg)
{
    register uint32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void gearsym_m4_put(const char *text)
{
    (void)semihost(SYS_WRITE0, text);
}

void gearsym_m4_exit(int status)
{
    /* 32-bit semihosting SYS_EXIT takes the reason code itself; a run-time error reports 1 */
    (void)semihost(SYS_EXIT, (const void *)(uintptr_t)(status == 0 ? ADP_STOPPED_APPLICATION_EXIT
                                                                    : ADP_STOPPED_RUN_TIME_ERROR));
    for (;;) {
    }
}

void gearsym_m4_fault(void)
{
    gearsym_m4_put("fault\n");
    gearsym_m4_exit(1);
}

void gearsym_m4_ticks_start(void)
{
    SYST_RVR = 0x00FFFFFFu; /* the full 24-bit range; no interrupt */
    SYST_CVR = 0u;
    SYST_CSR = 0x5u; /* enabled, processor clock */
}

uint32_t gearsym_m4_ticks(void)
{
    return SYST_CVR; /* counts down */
}

uint32_t gearsym_m4_calibration(uint32_t turns)
{
    const uint32_t start = SYST_CVR;
    __asm__ volatile("1:\n\tsubs %0, %0, #1\n\tbne 1b" : "+r"(turns) : : "cc");
    return (start - SYST_CVR) & 0x00FFFFFFu;
}

void gearsym_m4_reset(void)
{
    SCB_CPACR |= (0xFu << 20); /* CP10, CP11: full access to the FPU */
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    for (uint32_t *s = __data_load, *d = __data_start; d < __data_end;) {
        *d++ = *s++;
    }
    for (uint32_t *d = __bss_start; d < __bss_end;) {
        *d++ = 0u;
    }
    gearsym_m4_exit(main());
}
