/*
 * gearsym's Cortex-M4F driver of the TCU task: the emitted float shift controller of a shift
 * with its EKF (e.g. gearsym_control_2_3_tcu_task: EKF predict, update and mode update, then
 * the controller's step; control_case.h names the shift's through CTL() and EKF()) called
 * once per 10 ms tick along a recorded closed-loop shift
 * (control_case.h, written by gearsym.validation.checks.qemu_control). After each task the
 * commands, the phase and the EKF's state are printed as float bit patterns, so that the host
 * build and the emulated target can be compared exactly. On the target, SysTick counts each
 * task call (instructions under `-icount shift=0`).
 */
#include <stdint.h>
#include <string.h>

#include "control_case.h"
#include "harness.h"

#define NX EKF_NX
#define GEARSYM_LINE_CHARS (16 + 12 * (NX + 8))
#include "line_output.h"


int main(void)
{
    CTL(tcu_config) config;
    CTL(knowledge) knowledge;
    CTL(tcu_state) state;
    CTL(outputs) out;
    CTL(params_default)(&config.control);
    EKF(params_default)(&config.ekf);
    memcpy(config.q, case_q, sizeof config.q);
    memcpy(config.r, case_r, sizeof config.r);
    memcpy(config.y_floor, case_floor, sizeof config.y_floor);
    CTL(knowledge_default)(&knowledge);
    CTL(tcu_init)(&knowledge, case_x0, case_P0, &state);
#ifdef GEARSYM_M4_TARGET
    uint32_t t_empty = 0u, t_total = 0u, t_max = 0u;
    gearsym_m4_ticks_start();
    for (int i = 0; i < 64; ++i) {
        const uint32_t start = TICKS();
        t_empty += ELAPSED(start, TICKS());
    }
    report("empty64", t_empty);
    report("calibration", gearsym_m4_calibration(CASE_CALIBRATION_TURNS));
#endif
    for (int k = 0; k < CASE_TICKS; ++k) {
        CTL(tcu_inputs) in;
        in.control.t = case_in[k][0];
        in.control.omega_in = case_in[k][1];
        in.control.omega_out = case_in[k][2];
        in.omega_wheel = case_in[k][3];
        in.control.torque = case_in[k][4];
        CASE_SET_EXTRA(in, case_in[k]);
#ifdef GEARSYM_M4_TARGET
        const uint32_t t0 = TICKS();
#endif
        const int status = CTL(tcu_task)(&config, &knowledge, &in, &state, &out);
#ifdef GEARSYM_M4_TARGET
        const uint32_t elapsed = ELAPSED(t0, TICKS());
        t_total += elapsed;
        t_max = (elapsed > t_max) ? elapsed : t_max;
#endif
        put_word("ctl");
        put_hex((uint32_t)k);
        put_hex((uint32_t)status);
        put_hex((uint32_t)out.phase);
        put_real(out.p_off);
        put_real(out.p_on);
        for (int i = 0; i < NX; ++i) {
            put_real(state.x[i]);
        }
        flush();
    }
#ifdef GEARSYM_M4_TARGET
    report("ctl_ticks", (uint32_t)CASE_TICKS);
    report("ctl_total", t_total);
    report("ctl_max", t_max);
#endif
    put_word("done");
    flush();
    return 0;
}
