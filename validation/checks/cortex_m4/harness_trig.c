/* See harness_trig.h. */
#include "harness_trig.h"

#include <math.h>

#define GEARSYM_M4_TRIG_RANGE 0.8f

float gearsym_m4_sinf(float a)
{
    const float s = a * a;
    if (!(a <= GEARSYM_M4_TRIG_RANGE && a >= -GEARSYM_M4_TRIG_RANGE)) {
        return NAN;
    }
    /* a (1 - s/6 (1 - s/20 (1 - s/42 (1 - s/72 (1 - s/110))))) */
    return a * (1.0f - s * (1.0f / 6.0f)
                           * (1.0f - s * (1.0f / 20.0f)
                                         * (1.0f - s * (1.0f / 42.0f)
                                                       * (1.0f - s * (1.0f / 72.0f)
                                                                     * (1.0f - s * (1.0f / 110.0f))))));
}

float gearsym_m4_cosf(float a)
{
    const float s = a * a;
    if (!(a <= GEARSYM_M4_TRIG_RANGE && a >= -GEARSYM_M4_TRIG_RANGE)) {
        return NAN;
    }
    /* 1 - s/2 (1 - s/12 (1 - s/30 (1 - s/56 (1 - s/90 (1 - s/132))))) */
    return 1.0f - s * 0.5f
                      * (1.0f - s * (1.0f / 12.0f)
                                    * (1.0f - s * (1.0f / 30.0f)
                                                  * (1.0f - s * (1.0f / 56.0f)
                                                                * (1.0f - s * (1.0f / 90.0f)
                                                                              * (1.0f - s * (1.0f / 132.0f))))));
}
