/**
 * @file fmi2_glue.c
 * @brief Generic FMI 2.0 Model Exchange + Co-Simulation glue for gainlink's plant FMUs, on gl_fmu_core.h.
 *
 * A model source defines what gl_fmu_core.h lists, plus MODEL_GUID, before including this file.
 *
 * A Co-Simulation-only model (one whose state is not a set of continuous states, e.g. dead times)
 * defines GL_FMU_CS_ONLY instead of the state/derivative/partial/step items, and provides:
 *  - model_extra_t: state held outside the reals (e.g. delay lines), kept in the instance and
 *    saved and restored with it by fmi2GetFMUstate / fmi2SetFMUstate,
 *  - model_extra_reset(model_extra_t *x): its value at instantiation and fmi2Reset,
 *  - model_do_step(double *r, model_extra_t *x, double h, char *msg, size_t msg_size): advance one
 *    communication step of length h; on failure return non-zero with a message in msg and leave
 *    r and x unchanged (fmi2DoStep logs the message and returns fmi2Error).
 * The Model Exchange functions are then left out and fmi2GetDirectionalDerivative reports an error.
 *
 * No heap memory is used after fmi2Instantiate except the state copies requested through fmi2GetFMUstate.
 */
#include <stddef.h>
#include <string.h>

#include "fmi2Functions.h"
#include "gl_fmu_core.h"

typedef struct {
    double r[MODEL_N_REALS];
    double time;
#ifdef GL_FMU_CS_ONLY
    model_extra_t extra;
#endif
    fmi2Type type;
    fmi2CallbackFunctions cb;
    fmi2String name;
    int terminated;
} gl_fmu_t;

typedef struct {
    double r[MODEL_N_REALS];
    double time;
#ifdef GL_FMU_CS_ONLY
    model_extra_t extra;
#endif
} gl_fmu_snapshot_t;

static void gl_fmu_log(gl_fmu_t *c, fmi2Status status, const char *msg)
{
    if (c->cb.logger != NULL) {
        c->cb.logger(c->cb.componentEnvironment, c->name, status, "error", "%s", msg);
    }
}

/* Back to the values at instantiation: start values and, for a CS-only model, its extra state. */
static void gl_fmu_defaults(gl_fmu_t *c)
{
    gl_core_zero(c->r);
    model_set_defaults(c->r);
#ifdef GL_FMU_CS_ONLY
    model_extra_reset(&c->extra);
#endif
    model_derivatives(c->r);
}

/* ---- common functions ---- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[])
{
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging)
{
    (void)location; (void)visible; (void)logging;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        return NULL;
    }
    if (guid == NULL || strcmp(guid, MODEL_GUID) != 0) {
        if (functions->logger != NULL) {
            functions->logger(functions->componentEnvironment, name, fmi2Error, "error", "GUID mismatch");
        }
        return NULL;
    }
    gl_fmu_t *c = functions->allocateMemory(1, sizeof(gl_fmu_t));
    if (c == NULL) {
        return NULL;
    }
    c->cb = *functions;
    c->type = type;
    c->name = name;
    c->time = 0.0;
    c->terminated = 0;
    gl_fmu_defaults(c);
    return c;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (c != NULL) {
        gl_fmu_t *inst = c;
        inst->cb.freeMemory(inst);
    }
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDef, fmi2Real stop)
{
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((gl_fmu_t *)c)->time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    model_derivatives(((gl_fmu_t *)c)->r);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { ((gl_fmu_t *)c)->terminated = 1; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c)
{
    gl_fmu_t *inst = c;
    gl_fmu_defaults(inst);
    inst->time = 0.0;
    inst->terminated = 0;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (gl_core_get(((gl_fmu_t *)c)->r, vr, nvr, value) != 0) {
        gl_fmu_log(c, fmi2Error, "fmi2GetReal: unknown value reference");
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (gl_core_set(((gl_fmu_t *)c)->r, vr, nvr, value) != 0) {
        gl_fmu_log(c, fmi2Error, "fmi2SetReal: unknown value reference");
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no Integer variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no Boolean variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no String variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no Integer variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no Boolean variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)value;
    if (nvr > 0 && vr != NULL) { gl_fmu_log(c, fmi2Error, "no String variables"); return fmi2Error; }
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    gl_fmu_t *inst = c;
    gl_fmu_snapshot_t *s = *state;
    if (s == NULL) {
        s = inst->cb.allocateMemory(1, sizeof(gl_fmu_snapshot_t));
        if (s == NULL) {
            return fmi2Error;
        }
        *state = s;
    }
    memcpy(s->r, inst->r, sizeof(inst->r));
    s->time = inst->time;
#ifdef GL_FMU_CS_ONLY
    s->extra = inst->extra;
#endif
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    gl_fmu_t *inst = c;
    const gl_fmu_snapshot_t *s = state;
    if (s == NULL) {
        return fmi2Error;
    }
    memcpy(inst->r, s->r, sizeof(inst->r));
    inst->time = s->time;
#ifdef GL_FMU_CS_ONLY
    inst->extra = s->extra;
#endif
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    gl_fmu_t *inst = c;
    if (state != NULL && *state != NULL) {
        inst->cb.freeMemory(*state);
        *state = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)c; (void)state;
    *size = sizeof(gl_fmu_snapshot_t);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    (void)c;
    if (state == NULL || size < sizeof(gl_fmu_snapshot_t)) {
        return fmi2Error;
    }
    memcpy(bytes, state, sizeof(gl_fmu_snapshot_t));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    gl_fmu_t *inst = c;
    if (size != sizeof(gl_fmu_snapshot_t)) {
        return fmi2Error;
    }
    if (*state == NULL) {
        *state = inst->cb.allocateMemory(1, sizeof(gl_fmu_snapshot_t));
        if (*state == NULL) {
            return fmi2Error;
        }
    }
    memcpy(*state, bytes, sizeof(gl_fmu_snapshot_t));
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
#ifdef GL_FMU_CS_ONLY
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    gl_fmu_log(c, fmi2Error, "fmi2GetDirectionalDerivative: not provided by this FMU");
    return fmi2Error;
#else
    const char *err = gl_core_directional(((gl_fmu_t *)c)->r, vUnknown, nUnknown, vKnown, nKnown, dvKnown, dvUnknown);
    if (err != NULL) {
        gl_fmu_log(c, fmi2Error, err);
        return fmi2Error;
    }
    return fmi2OK;
#endif
}

#ifndef GL_FMU_CS_ONLY
/* ---- Model Exchange ---- */

fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    (void)c;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)c; (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { ((gl_fmu_t *)c)->time = time; return fmi2OK; }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    if (nx != MODEL_N_STATES) {
        return fmi2Error;
    }
    gl_core_set_states(((gl_fmu_t *)c)->r, x);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx)
{
    if (nx != MODEL_N_STATES) {
        return fmi2Error;
    }
    gl_core_get_derivatives(((gl_fmu_t *)c)->r, dx);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz)
{
    (void)c; (void)z;
    return nz == 0 ? fmi2OK : fmi2Error;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    if (nx != MODEL_N_STATES) {
        return fmi2Error;
    }
    gl_core_get_states(((gl_fmu_t *)c)->r, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real nominals[], size_t nx)
{
    (void)c;
    for (size_t i = 0; i < nx; i++) {
        nominals[i] = 1.0;
    }
    return fmi2OK;
}
#endif /* GL_FMU_CS_ONLY */

/* ---- Co-Simulation ---- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    gl_fmu_t *inst = c;
    (void)noSetFMUStatePriorToCurrentPoint;
#ifdef GL_FMU_CS_ONLY
    char msg[256] = "fmi2DoStep failed";
    if (!(h >= 0.0)) {
        gl_fmu_log(inst, fmi2Error, "fmi2DoStep: negative step");
        return fmi2Error;
    }
    if (model_do_step(inst->r, &inst->extra, h, msg, sizeof msg) != 0) {
        gl_fmu_log(inst, fmi2Error, msg);
        return fmi2Error;
    }
    model_derivatives(inst->r);
#else
    const char *err = gl_core_do_step(inst->r, h);
    if (err != NULL) {
        gl_fmu_log(inst, fmi2Error, err);
        return fmi2Error;
    }
#endif
    inst->time = t + h;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)c; (void)s; *value = fmi2OK; return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    gl_fmu_t *inst = c;
    if (s == fmi2LastSuccessfulTime) {
        *value = inst->time;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)c; (void)s; (void)value; return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)c; (void)s; (void)value; return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)c; (void)s; (void)value; return fmi2Discard;
}
