/*
 * The same sine and cosine on the host and on the target, for the bit-for-bit comparison only:
 * glibc's and newlib's sinf/cosf are different implementations and may differ in the last bit
 * (validation/checks/qemu_m4.py). These use +, - and * alone (correctly rounded on both, with
 * -ffp-contract=off), so both builds give the same bits. Taylor polynomials for the road
 * grade's range: |a| <= 0.8 rad (truncation below 1e-11 there); NaN outside it, so that a
 * wider argument shows instead of giving a wrong value.
 */
#ifndef GEARSYM_M4_HARNESS_TRIG_H
#define GEARSYM_M4_HARNESS_TRIG_H

float gearsym_m4_sinf(float a);
float gearsym_m4_cosf(float a);

#endif /* GEARSYM_M4_HARNESS_TRIG_H */
