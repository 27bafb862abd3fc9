/**
 * @file cart_pendulum3.c
 * @brief The nonlinear cart pendulum (cart_pendulum_model.h) as an FMI 3.0 Co-Simulation FMU.
 */
#define MODEL_TOKEN "{2b9d1c34-6e0f-4b8a-a1d2-3c4e5f60718f}"

#include "cart_pendulum_model.h"
#include "fmi3_glue.c"
