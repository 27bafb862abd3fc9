/**
 * @file cart_pendulum.c
 * @brief Nonlinear cart with an inverted point-mass pendulum, FMI 2.0 (ME + CS); model in cart_pendulum_model.h.
 */
#define MODEL_GUID "{8c4e810f-3df3-4a00-8276-176fa3c9f001}"

#include "cart_pendulum_model.h"
#include "fmi2_glue.c"
