/**
 * @file fmi3_glue.c
 * @brief Generic FMI 3.0 Model Exchange + Co-Simulation glue for gainlink's plant FMUs (Float64 variables only),
 *        on gl_fmu_core.h.
 *
 * A model source defines what gl_fmu_core.h lists, plus MODEL_TOKEN (the instantiation token), before including
 * this file; GL_FMU_ME_ONLY makes fmi3InstantiateCoSimulation refuse (for an FMU whose modelDescription.xml
 * declares Model Exchange only). Every function of the FMI 3.0 API is defined (fmpy resolves all of them); what
 * the FMU does not support returns fmi3Error.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "gl_fmu_core.h"

typedef struct {
    double r[MODEL_N_REALS];
    double time;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} gl_fmu3_t;

typedef struct {
    double r[MODEL_N_REALS];
    double time;
} gl_fmu3_snapshot_t;

static void gl3_log(gl_fmu3_t *c, fmi3Status status, const char *msg)
{
    if (c != NULL && c->log != NULL) {
        c->log(c->env, status, "logStatusError", msg);
    }
}

/* An instance at its start values (both interfaces), or NULL when the token does not match. */
static gl_fmu3_t *gl3_instantiate(fmi3String token, fmi3InstanceEnvironment env, fmi3LogMessageCallback logMessage)
{
    if (token == NULL || strcmp(token, MODEL_TOKEN) != 0) {
        if (logMessage != NULL) {
            logMessage(env, fmi3Error, "logStatusError", "instantiation token mismatch");
        }
        return NULL;
    }
    gl_fmu3_t *c = calloc(1, sizeof *c);
    if (c == NULL) {
        return NULL;
    }
    c->env = env;
    c->log = logMessage;
    gl_core_zero(c->r);
    model_set_defaults(c->r);
    model_derivatives(c->r);
    return c;
}

#define GL3_UNSUPPORTED(inst) do { gl3_log((gl_fmu3_t *)(inst), fmi3Error, "not supported by this FMU"); \
    return fmi3Error; } while (0)

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    (void)instance; (void)loggingOn; (void)nCategories; (void)categories;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)resourcePath; (void)visible; (void)loggingOn;
    return gl3_instantiate(instantiationToken, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)instanceName; (void)resourcePath; (void)visible; (void)loggingOn; (void)eventModeUsed;
    (void)earlyReturnAllowed; (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
#ifdef GL_FMU_ME_ONLY
    (void)instantiationToken;
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU has no Co-Simulation interface");
    }
    return NULL;
#else
    return gl3_instantiate(instantiationToken, instanceEnvironment, logMessage);
#endif
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "no Scheduled Execution interface");
    }
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ((gl_fmu3_t *)instance)->time = startTime;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    model_derivatives(((gl_fmu3_t *)instance)->r);
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { (void)instance; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance instance) { (void)instance; return fmi3OK; }

fmi3Status fmi3Reset(fmi3Instance instance)
{
    gl_fmu3_t *c = instance;
    gl_core_zero(c->r);
    model_set_defaults(c->r);
    model_derivatives(c->r);
    c->time = 0.0;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    gl_fmu3_t *c = instance;
    if (nValues < nvr) {
        GL3_UNSUPPORTED(instance);
    }
    if (gl_core_get(c->r, vr, nvr, values) != 0) {
        gl3_log(c, fmi3Error, "fmi3GetFloat64: unknown value reference");
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    gl_fmu3_t *c = instance;
    if (nValues < nvr) {
        GL3_UNSUPPORTED(instance);
    }
    if (gl_core_set(c->r, vr, nvr, values) != 0) {
        gl3_log(c, fmi3Error, "fmi3SetFloat64: unknown value reference");
        return fmi3Error;
    }
    return fmi3OK;
}

/* Every other variable type: this FMU has none. */
#define GL3_NO_GET(NAME, T) \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, T values[], size_t nValues) \
    { (void)vr; (void)values; (void)nValues; if (nvr == 0) { return fmi3OK; } GL3_UNSUPPORTED(instance); }
#define GL3_NO_SET(NAME, T) \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const T values[], \
                    size_t nValues) \
    { (void)vr; (void)values; (void)nValues; if (nvr == 0) { return fmi3OK; } GL3_UNSUPPORTED(instance); }

GL3_NO_GET(fmi3GetFloat32, fmi3Float32)
GL3_NO_GET(fmi3GetInt8, fmi3Int8)
GL3_NO_GET(fmi3GetUInt8, fmi3UInt8)
GL3_NO_GET(fmi3GetInt16, fmi3Int16)
GL3_NO_GET(fmi3GetUInt16, fmi3UInt16)
GL3_NO_GET(fmi3GetInt32, fmi3Int32)
GL3_NO_GET(fmi3GetUInt32, fmi3UInt32)
GL3_NO_GET(fmi3GetInt64, fmi3Int64)
GL3_NO_GET(fmi3GetUInt64, fmi3UInt64)
GL3_NO_GET(fmi3GetBoolean, fmi3Boolean)
GL3_NO_GET(fmi3GetString, fmi3String)
GL3_NO_SET(fmi3SetFloat32, fmi3Float32)
GL3_NO_SET(fmi3SetInt8, fmi3Int8)
GL3_NO_SET(fmi3SetUInt8, fmi3UInt8)
GL3_NO_SET(fmi3SetInt16, fmi3Int16)
GL3_NO_SET(fmi3SetUInt16, fmi3UInt16)
GL3_NO_SET(fmi3SetInt32, fmi3Int32)
GL3_NO_SET(fmi3SetUInt32, fmi3UInt32)
GL3_NO_SET(fmi3SetInt64, fmi3Int64)
GL3_NO_SET(fmi3SetUInt64, fmi3UInt64)
GL3_NO_SET(fmi3SetBoolean, fmi3Boolean)
GL3_NO_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0) { return fmi3OK; }
    GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0) { return fmi3OK; }
    GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    (void)vr; (void)nvr; (void)values; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    (void)vr; (void)nvr; (void)values; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference vr, size_t *n)
{
    (void)vr; (void)n; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    gl_fmu3_t *c = instance;
    gl_fmu3_snapshot_t *s = *state;
    if (s == NULL) {
        s = malloc(sizeof *s);
        if (s == NULL) {
            return fmi3Error;
        }
        *state = s;
    }
    memcpy(s->r, c->r, sizeof c->r);
    s->time = c->time;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    gl_fmu3_t *c = instance;
    const gl_fmu3_snapshot_t *s = state;
    if (s == NULL) {
        return fmi3Error;
    }
    memcpy(c->r, s->r, sizeof c->r);
    c->time = s->time;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    (void)instance;
    if (state != NULL) {
        free(*state);
        *state = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    (void)instance; (void)state;
    *size = sizeof(gl_fmu3_snapshot_t);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte bytes[], size_t size)
{
    (void)instance;
    if (state == NULL || size < sizeof(gl_fmu3_snapshot_t)) {
        return fmi3Error;
    }
    memcpy(bytes, state, sizeof(gl_fmu3_snapshot_t));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte bytes[], size_t size, fmi3FMUState *state)
{
    (void)instance;
    if (size != sizeof(gl_fmu3_snapshot_t)) {
        return fmi3Error;
    }
    if (*state == NULL) {
        *state = malloc(sizeof(gl_fmu3_snapshot_t));
        if (*state == NULL) {
            return fmi3Error;
        }
    }
    memcpy(*state, bytes, sizeof(gl_fmu3_snapshot_t));
    return fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    gl_fmu3_t *c = instance;
    if (nSeed != nKnowns || nSensitivity != nUnknowns) {
        gl3_log(c, fmi3Error, "fmi3GetDirectionalDerivative: one seed per known, one sensitivity per unknown");
        return fmi3Error;
    }
    const char *err = gl_core_directional(c->r, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity);
    if (err != NULL) {
        gl3_log(c, fmi3Error, err);
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { GL3_UNSUPPORTED(instance); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { GL3_UNSUPPORTED(instance); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr; (void)nvr; (void)intervals; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { (void)instance; return fmi3OK; }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)instance;
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

/* ---- Model Exchange ---- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { (void)instance; return fmi3OK; }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)instance; (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { ((gl_fmu3_t *)instance)->time = time; return fmi3OK; }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t n)
{
    if (n != MODEL_N_STATES) {
        GL3_UNSUPPORTED(instance);
    }
    gl_core_set_states(((gl_fmu3_t *)instance)->r, x);
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 dx[], size_t n)
{
    if (n != MODEL_N_STATES) {
        GL3_UNSUPPORTED(instance);
    }
    gl_core_get_derivatives(((gl_fmu3_t *)instance)->r, dx);
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 z[], size_t n)
{
    (void)z;
    if (n != 0) {
        GL3_UNSUPPORTED(instance);
    }
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n)
{
    if (n != MODEL_N_STATES) {
        GL3_UNSUPPORTED(instance);
    }
    gl_core_get_states(((gl_fmu3_t *)instance)->r, x);
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t n)
{
    (void)instance;
    for (size_t i = 0; i < n; i++) {
        nominals[i] = 1.0;
    }
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n) { (void)instance; *n = 0; return fmi3OK; }

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n)
{
    (void)instance;
    *n = MODEL_N_STATES;
    return fmi3OK;
}

/* ---- Co-Simulation ---- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) { (void)instance; return fmi3OK; }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues; GL3_UNSUPPORTED(instance);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    gl_fmu3_t *c = instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    const char *err = gl_core_do_step(c->r, communicationStepSize);
    if (err != NULL) {
        gl3_log(c, fmi3Error, err);
        *lastSuccessfulTime = c->time;
        return fmi3Error;
    }
    c->time = currentCommunicationPoint + communicationStepSize;
    *lastSuccessfulTime = c->time;
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime; GL3_UNSUPPORTED(instance);
}
