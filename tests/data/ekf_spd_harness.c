/*
 * 10^6 steps of the emitted EKF (predict + update) in the working precision: after every step
 * P must be exactly symmetric and positive definite (Cholesky in double of the stored P,
 * every pivot > 0). Measurements are the filter's own predicted speeds plus Gaussian noise of
 * P must be exactly symmetric and positive definite (Cholesky in double of the scaled P, every
 * pivot > 0). The truth is the same model stepped by the emitted rk4_step with m_veh 1800 kg,
 * mu 0.11, zeta 0; the measurements are its speeds plus Gaussian noise of the (3.26) size. The
 * element modes cycle through gear 2, both sliding, B05 sliding and gear 3 every 10 s; the
 * input speed is put back on the next gear's ratio at each gear change (as lock-up does) and
 * the input torque keeps the wheel near 25 rad/s (+-150 N m). Prints "ok <min pivot> ...".
 */
#include <math.h>
#include <stdio.h>

#include "gearsym_ekf_2_3.h"

#define NX GEARSYM_EKF_2_3_NX
#define NY GEARSYM_EKF_2_3_NY

static unsigned long long lcg_state = 12345u;

static double uniform(void)
{
    lcg_state = lcg_state * 6364136223846793005ull + 1442695040888963407ull;
    return ((double)(lcg_state >> 11) + 0.5) / 9007199254740992.0;
}

static double gauss(void)
{
    return sqrt(-2.0 * log(uniform())) * cos(6.283185307179586 * uniform());
}

int main(void)
{
    gearsym_ekf_2_3_params p;
    gearsym_real x[NX] = {194.89, 60.09, 0.0578, 24.34, 1260.0, 0.12, 0.12, 0.0};
    gearsym_real truth[NX] = {194.89, 60.09, 0.0578, 24.34, 1800.0, 0.11, 0.11, 0.0};
    gearsym_real P[NX * NX] = {0};
    const gearsym_real sig0[NX] = {1.95, 0.6, 0.05, 0.25, 540.0, 0.03, 0.03, 0.05};
    const gearsym_real q[NX] = {12.0, 0.3, 3e-6, 0.03, 1.0, 4e-3, 4e-3, 2.5e-5};
    const gearsym_real r[NY] = {0.01, 0.01, 0.01};
    const gearsym_real y_floor[NY] = {2.0, 0.7, 0.27};
    const gearsym_real h = GEARSYM_LIT(0.01);
    double min_pivot = 1e300;
    long step;
    int i;
    int j;
    int k;

    gearsym_ekf_2_3_params_default(&p);
    for (i = 0; i < NX; ++i) {
        P[i + i * NX] = sig0[i] * sig0[i];
    }
    for (step = 0; step < 1000000L; ++step) {
        const long phase = step % 1000;
        const long cycle = step / 1000;
        gearsym_real u[GEARSYM_EKF_2_3_NU] = {0};
        gearsym_real y_hat[NY];
        gearsym_real y[NY];
        gearsym_real nis;
        double L[NX * NX];

        (void)cycle;
        u[0] = (truth[3] > GEARSYM_LIT(25.0)) ? GEARSYM_LIT(-150.0) : GEARSYM_LIT(150.0);
        if (phase < 460) { /* gear 2: K38 sticks */
            u[4] = GEARSYM_LIT(1.0);
            u[1] = GEARSYM_LIT(9750.0);
            if (phase == 0) {
                truth[0] = GEARSYM_LIT(3.243) * truth[1];
            }
        } else if (phase < 480) { /* torque phase: both slide */
            u[1] = GEARSYM_LIT(1240.0);
            u[2] = GEARSYM_LIT(300.0);
            u[3] = GEARSYM_LIT(1.0);
            u[5] = GEARSYM_LIT(1.0);
        } else if (phase < 500) { /* speed phase: B05 slides */
            u[2] = GEARSYM_LIT(910.0);
            u[5] = GEARSYM_LIT(1.0);
        } else { /* gear 3: B05 sticks */
            u[2] = GEARSYM_LIT(10500.0);
            u[6] = GEARSYM_LIT(1.0);
            if (phase == 500) {
                truth[0] = GEARSYM_LIT(2.252) * truth[1];
            }
        }
        gearsym_ekf_2_3_ekf_predict(x, P, u, &p, h, q);
        gearsym_ekf_2_3_rk4_step(truth, u, &p, h, truth);
        gearsym_ekf_2_3_outputs(truth, u, &p, y_hat);
        for (i = 0; i < NY; ++i) {
            const double level = fabs((double)y_hat[i]) > (double)y_floor[i] ? fabs((double)y_hat[i]) : (double)y_floor[i];
            y[i] = (gearsym_real)((double)y_hat[i] + 0.01 * level * gauss());
        }
        (void)gearsym_ekf_2_3_ekf_update(x, P, u, &p, y, r, y_floor, &nis);
        /* symmetric to the bit, and Cholesky in double of the scaled P */
        for (j = 0; j < NX; ++j) {
            for (i = 0; i < NX; ++i) {
                if (P[i + j * NX] != P[j + i * NX] || !isfinite(P[i + j * NX])) {
                    printf("fail asymmetric or non-finite at step %ld: x %g %g %g %g %g %g %g %g P %g\n", step, (double)x[0], (double)x[1], (double)x[2], (double)x[3], (double)x[4], (double)x[5], (double)x[6], (double)x[7], (double)P[i + j * NX]);
                    return 1;
                }
                L[i + j * NX] = (double)P[i + j * NX] / ((double)sig0[i] * (double)sig0[j]);
            }
        }
        for (j = 0; j < NX; ++j) {
            double d = L[j + j * NX];
            for (k = 0; k < j; ++k) {
                d -= L[j + k * NX] * L[j + k * NX];
            }
            if (!(d > 0.0)) {
                printf("fail not positive definite at step %ld\n", step);
                return 1;
            }
            if (d < min_pivot) {
                min_pivot = d;
            }
            L[j + j * NX] = sqrt(d);
            for (i = j + 1; i < NX; ++i) {
                double s = L[i + j * NX];
                for (k = 0; k < j; ++k) {
                    s -= L[i + k * NX] * L[j + k * NX];
                }
                L[i + j * NX] = s / L[j + j * NX];
            }
        }
    }
    printf("ok %.6g m_veh %.6g sigma %.6g omega_C %.6g (truth %.6g)\n", min_pivot, (double)x[4],
           sqrt((double)P[4 + 4 * NX]), (double)x[3], (double)truth[3]);
    return 0;
}
