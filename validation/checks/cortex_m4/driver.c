/*
 * gearsym's Cortex-M4F driver: the emitted float EKF of the 2-3 shift (predict + update, thesis
 * 4.3) along a measured shift, the emitted float extended UIO's euio_step (4.5) along the same
 * shift (on its own state, with the library run's held masks and dropouts), and RK4 steps of the emitted 2-3 shift model (2.42-2.58), of its
 * mu form (2.69) and of the full model, on the data of case_data.h (written by gearsym.validation.checks.qemu_m4). Every result is printed as the
 * bit pattern of its float, so that the host build and the emulated target can be compared
 * exactly. On the target, SysTick counts the time of each step (instructions under
 * `-icount shift=0`).
 */
#include <stdint.h>
#include <string.h>

#include "case_data.h"
#include "gearsym_ekf_2_3.h"
#include "gearsym_euio_2_3.h"
#include "gearsym_full.h"
#include "gearsym_shift_2_3.h"
#include "gearsym_shift_2_3_mu.h"
#include "harness.h"

#define NX GEARSYM_EKF_2_3_NX
#define NS GEARSYM_SHIFT_2_3_NX
#define NF GEARSYM_FULL_NX
#define NE GEARSYM_EUIO_2_3_NX

/* One model's RK4 run along CASE_SHIFT_STEPS samples, every state printed after each step. */
#define RUN_RK4(tag, step, n, params, x0, u)                      \
    do {                                                         \
        float state_[n];                                         \
        memcpy(state_, (x0), sizeof state_);                     \
        for (int k_ = 0; k_ < CASE_SHIFT_STEPS; ++k_) {          \
            step(state_, (u)[k_], (params), CASE_SHIFT_H, state_); \
            put_word(tag);                                       \
            put_hex((uint32_t)k_);                               \
            for (int i_ = 0; i_ < (n); ++i_) {                   \
                put_real(state_[i_]);                            \
            }                                                    \
            flush();                                             \
        }                                                        \
    } while (0)

/* The same run timed as one loop, nothing printed inside; reports the ticks and end state. */
#define TIME_RK4(tag, step, n, params, x0, u)                    \
    do {                                                         \
        float state_[n];                                         \
        memcpy(state_, (x0), sizeof state_);                     \
        const uint32_t start_ = TICKS();                         \
        for (int k_ = 0; k_ < CASE_SHIFT_STEPS; ++k_) {          \
            step(state_, (u)[k_], (params), CASE_SHIFT_H, state_); \
        }                                                        \
        const uint32_t end_ = TICKS();                           \
        report(tag "_total", ELAPSED(start_, end_));             \
        put_word(tag "_check");                                  \
        for (int i_ = 0; i_ < (n); ++i_) {                       \
            put_real(state_[i_]);                                \
        }                                                        \
        flush();                                                 \
    } while (0)

#define GEARSYM_LINE_CHARS (16 + 12 * (NX + NX * NX + 4))
#include "line_output.h"

int main(void)
{
    float x[NX], P[NX * NX], nis = 0.0f;
    gearsym_ekf_2_3_params pe;
    gearsym_shift_2_3_params ps;
    gearsym_shift_2_3_mu_params pm;
    gearsym_full_params pf;
    gearsym_ekf_2_3_params_default(&pe);
    gearsym_shift_2_3_params_default(&ps);
    gearsym_shift_2_3_mu_params_default(&pm);
    gearsym_full_params_default(&pf);
    memcpy(x, case_x0, sizeof x);
    memcpy(P, case_P0, sizeof P);
#ifdef GEARSYM_M4_TARGET
    uint32_t t_predict = 0u, t_update = 0u, t_empty = 0u;
    gearsym_m4_ticks_start();
    for (int i = 0; i < 64; ++i) {
        const uint32_t start = TICKS();
        t_empty += ELAPSED(start, TICKS());
    }
    report("empty64", t_empty);
    report("calibration", gearsym_m4_calibration(CASE_CALIBRATION_TURNS));
#endif
    for (int k = 1; k < CASE_EKF_STEPS; ++k) {
#ifdef GEARSYM_M4_TARGET
        const uint32_t t0 = TICKS();
#endif
        gearsym_ekf_2_3_ekf_predict(x, P, case_u[k - 1], &pe, CASE_H, case_q);
#ifdef GEARSYM_M4_TARGET
        const uint32_t t1 = TICKS();
#endif
        const int n = gearsym_ekf_2_3_ekf_update(x, P, case_u[k], &pe, case_y[k], case_r,
                                                 case_floor, &nis);
#ifdef GEARSYM_M4_TARGET
        const uint32_t t2 = TICKS();
        t_predict += ELAPSED(t0, t1);
        t_update += ELAPSED(t1, t2);
#endif
        put_word("ekf");
        put_hex((uint32_t)k);
        put_hex((uint32_t)n);
        put_real(nis);
        for (int i = 0; i < NX; ++i) {
            put_real(x[i]);
        }
        for (int i = 0; i < NX * NX; ++i) {
            put_real(P[i]);
        }
        flush();
    }
    {
        float xe[NE], Pe[NE * NE], load[3];
        gearsym_euio_2_3_params pu;
        gearsym_euio_2_3_params_default(&pu);
        memcpy(xe, case_euio_x0, sizeof xe);
        memcpy(Pe, case_euio_P0, sizeof Pe);
#ifdef GEARSYM_M4_TARGET
        uint32_t t_euio = 0u;
#endif
        for (int k = 1; k < CASE_EUIO_STEPS; ++k) {
#ifdef GEARSYM_M4_TARGET
            const uint32_t t0 = TICKS();
#endif
            const int status = gearsym_euio_2_3_euio_step(
                xe, Pe, case_euio_u[k - 1], case_euio_u[k], &pu, CASE_H, case_euio_q,
                case_euio_y[k], case_euio_r, case_euio_floor, case_euio_held[k], load);
#ifdef GEARSYM_M4_TARGET
            t_euio += ELAPSED(t0, TICKS());
#endif
            put_word("euio");
            put_hex((uint32_t)k);
            put_hex((uint32_t)status);
            for (int i = 0; i < 3; ++i) {
                put_real(load[i]);
            }
            for (int i = 0; i < NE; ++i) {
                put_real(xe[i]);
            }
            for (int i = 0; i < NE * NE; ++i) {
                put_real(Pe[i]);
            }
            flush();
        }
#ifdef GEARSYM_M4_TARGET
        report("euio_steps", (uint32_t)(CASE_EUIO_STEPS - 1));
        report("euio_step", t_euio);
#endif
    }
    RUN_RK4("rk4", gearsym_shift_2_3_rk4_step, NS, &ps, case_shift_x0, case_shift_u);
    RUN_RK4("rk4mu", gearsym_shift_2_3_mu_rk4_step, NS, &pm, case_shift_x0, case_mu_u);
    RUN_RK4("rk4full", gearsym_full_rk4_step, NF, &pf, case_full_x0, case_full_u);
#ifdef GEARSYM_M4_TARGET
    report("ekf_steps", (uint32_t)(CASE_EKF_STEPS - 1));
    report("ekf_predict", t_predict);
    report("ekf_update", t_update);
    report("rk4_steps", (uint32_t)CASE_SHIFT_STEPS);
    TIME_RK4("rk4", gearsym_shift_2_3_rk4_step, NS, &ps, case_shift_x0, case_shift_u);
    TIME_RK4("rk4mu", gearsym_shift_2_3_mu_rk4_step, NS, &pm, case_shift_x0, case_mu_u);
    TIME_RK4("rk4full", gearsym_full_rk4_step, NF, &pf, case_full_x0, case_full_u);
#endif
    put_word("done");
    flush();
    return 0;
}
