/* Host side of gearsym's Cortex-M4F harness: the driver's text goes to stdout. */
#include <stdio.h>

#include "harness.h"

void gearsym_m4_put(const char *text)
{
    (void)fputs(text, stdout);
}
