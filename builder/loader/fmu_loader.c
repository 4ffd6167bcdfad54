/* pantohil FMU loader: the FMU's binaries/<platform>/<modelIdentifier> library.

   pythonfmu's library runs the FMU's Python class in an embedded interpreter but does not link
   libpython: a host without Python of its own fails with "undefined symbol: _Py_NoneStruct", and
   libpython's extension modules (numpy) need its symbols global. This library, compiled by
   `pantohil build` for each FMU, therefore
   - opens libpython with RTLD_GLOBAL when the process has no Python yet (PANTOHIL_LIBPYTHON, or the
     path recorded at build time), sets PYTHONHOME / PYTHONPATH (if unset) to the interpreter and
     site-packages that numpy and scipy came from at build time, and starts the interpreter, which it
     never finalizes (see start_python);
   - then opens pythonfmu's library (PANTOHIL_INNER, next to this one) and forwards every FMI 2.0
     call to it;
   - enforces the fixed communication step (canHandleVariableCommunicationStepSize="false"): a doStep
     within 1e-6 of the FMU's time_step is a step of time_step, a remainder below 1e-3 of it is taken
     without a model step (the outputs hold), and any other step returns fmi2Error with a logged message;
   - always passes the embedded Python's error messages to the host's logger (pythonfmu drops them
     unless logging is on), so that a missing module is named;
   - releases pythonfmu's interpreter state from an exit handler (see release_python_state_at_exit).
   Compile-time definitions: PANTOHIL_LIBPYTHON, PANTOHIL_PYTHONHOME, PANTOHIL_PYTHONPATH,
   PANTOHIL_INNER, PANTOHIL_TIME_STEP_VR. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "fmi2Functions.h"

#define MESSAGE_SIZE 4096

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;     /* the host's callbacks */
    fmi2CallbackFunctions wrapped;  /* what pythonfmu's library gets: our logger */
    char *name;
    int host_logging;
    double time_step_s;             /* the only communication step this FMU takes (0: not known yet) */
    char error[MESSAGE_SIZE];       /* pythonfmu's last error message, for fmi2Instantiate's own */
} Instance;

/* pythonfmu's FMI functions, resolved once */
static struct {
    void *lib;
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetDebugLoggingTYPE *set_debug_logging;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_initialization_mode;
    fmi2ExitInitializationModeTYPE *exit_initialization_mode;
    fmi2TerminateTYPE *terminate;
    fmi2ResetTYPE *reset;
    fmi2GetRealTYPE *get_real;
    fmi2GetIntegerTYPE *get_integer;
    fmi2GetBooleanTYPE *get_boolean;
    fmi2GetStringTYPE *get_string;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2SetStringTYPE *set_string;
    fmi2GetFMUstateTYPE *get_fmu_state;
    fmi2SetFMUstateTYPE *set_fmu_state;
    fmi2FreeFMUstateTYPE *free_fmu_state;
    fmi2SerializedFMUstateSizeTYPE *serialized_fmu_state_size;
    fmi2SerializeFMUstateTYPE *serialize_fmu_state;
    fmi2DeSerializeFMUstateTYPE *deserialize_fmu_state;
    fmi2GetDirectionalDerivativeTYPE *get_directional_derivative;
    fmi2SetRealInputDerivativesTYPE *set_real_input_derivatives;
    fmi2GetRealOutputDerivativesTYPE *get_real_output_derivatives;
    fmi2DoStepTYPE *do_step;
    fmi2CancelStepTYPE *cancel_step;
    fmi2GetStatusTYPE *get_status;
    fmi2GetRealStatusTYPE *get_real_status;
    fmi2GetIntegerStatusTYPE *get_integer_status;
    fmi2GetBooleanStatusTYPE *get_boolean_status;
    fmi2GetStringStatusTYPE *get_string_status;
} py;

static void say(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status, const char *fmt, ...) {
    char text[MESSAGE_SIZE];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    if (cb != NULL && cb->logger != NULL)
        cb->logger(cb->componentEnvironment, name, status, "logStatusError", "%s", text);
    else
        fprintf(stderr, "%s: %s\n", name ? name : "pantohil FMU", text);
}

/* pythonfmu's messages: errors always reach the host, the rest only when the host asked for logging */
static void relay(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                  fmi2String message, ...) {
    Instance *inst = (Instance *)env;
    char text[MESSAGE_SIZE];
    va_list args;
    if (!inst->host_logging && status < fmi2Error)
        return;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    if (status >= fmi2Error)
        memcpy(inst->error, text, sizeof text);
    if (inst->host.logger != NULL)
        inst->host.logger(inst->host.componentEnvironment, name, status, category, "%s", text);
}

static void set_default_env(const char *name, const char *value) {
    if (value[0] != '\0' && getenv(name) == NULL)
        setenv(name, value, 0);
}

/* In a host without Python the loader starts the interpreter itself, before pythonfmu's library would:
   pythonfmu finalizes only an interpreter it started, and Py_Finalize with scipy loaded crashes at the
   process's exit (scipy's _uarray module frees its globals while objects still point into them:
   SIGSEGV in the collector after the run's work is done). An interpreter started here is never
   finalized; the exit reclaims it. Py_InitializeEx(0) leaves the host's signal handlers alone, and the
   GIL is released so that pythonfmu takes it on whichever thread calls. */
static int start_python(void *lib, const fmi2CallbackFunctions *cb, fmi2String name, const char *path) {
    int (*is_initialized)(void);
    void (*initialize)(int);
    void *(*save_thread)(void);
    *(void **)&is_initialized = dlsym(lib, "Py_IsInitialized");
    *(void **)&initialize = dlsym(lib, "Py_InitializeEx");
    *(void **)&save_thread = dlsym(lib, "PyEval_SaveThread");
    if (is_initialized == NULL || initialize == NULL || save_thread == NULL) {
        say(cb, name, fmi2Error, "pantohil FMU: %s is not a libpython (no Py_InitializeEx)", path);
        return 0;
    }
    if (!is_initialized()) {
        initialize(0);
        save_thread();
    }
    return 1;
}

/* libpython with global symbols, unless the process already has an interpreter (a Python host) */
static int load_python(const fmi2CallbackFunctions *cb, fmi2String name) {
    const char *path;
    void *lib;
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL)
        return 1;
    path = getenv("PANTOHIL_LIBPYTHON");
    if (path == NULL || path[0] == '\0')
        path = PANTOHIL_LIBPYTHON;
    if (path[0] == '\0') {
        say(cb, name, fmi2Error, "pantohil FMU needs libpython 3.%s with numpy and scipy: set PANTOHIL_LIBPYTHON "
            "to its path (this FMU was built by a Python without a shared libpython)", PANTOHIL_PY_MINOR);
        return 0;
    }
    if ((lib = dlopen(path, RTLD_NOW | RTLD_GLOBAL)) == NULL) {
        say(cb, name, fmi2Error, "pantohil FMU needs libpython 3.%s with numpy and scipy: cannot open %s (%s); "
            "set PANTOHIL_LIBPYTHON to its path", PANTOHIL_PY_MINOR, path, dlerror());
        return 0;
    }
    set_default_env("PYTHONHOME", PANTOHIL_PYTHONHOME);
    set_default_env("PYTHONPATH", PANTOHIL_PYTHONPATH);
    return start_python(lib, cb, name, path);
}

#define RESOLVE(field, symbol)                                                          \
    if ((py.field = (symbol##TYPE *)dlsym(py.lib, #symbol)) == NULL) {                  \
        say(cb, name, fmi2Error, "pantohil FMU: %s lacks %s", inner_path, #symbol);     \
        return 0;                                                                       \
    }

static int resolve_all(const fmi2CallbackFunctions *cb, fmi2String name, const char *inner_path) {
    RESOLVE(instantiate, fmi2Instantiate) RESOLVE(free_instance, fmi2FreeInstance)
    RESOLVE(set_debug_logging, fmi2SetDebugLogging) RESOLVE(setup_experiment, fmi2SetupExperiment)
    RESOLVE(enter_initialization_mode, fmi2EnterInitializationMode)
    RESOLVE(exit_initialization_mode, fmi2ExitInitializationMode)
    RESOLVE(terminate, fmi2Terminate) RESOLVE(reset, fmi2Reset)
    RESOLVE(get_real, fmi2GetReal) RESOLVE(get_integer, fmi2GetInteger)
    RESOLVE(get_boolean, fmi2GetBoolean) RESOLVE(get_string, fmi2GetString)
    RESOLVE(set_real, fmi2SetReal) RESOLVE(set_integer, fmi2SetInteger)
    RESOLVE(set_boolean, fmi2SetBoolean) RESOLVE(set_string, fmi2SetString)
    RESOLVE(get_fmu_state, fmi2GetFMUstate) RESOLVE(set_fmu_state, fmi2SetFMUstate)
    RESOLVE(free_fmu_state, fmi2FreeFMUstate) RESOLVE(serialized_fmu_state_size, fmi2SerializedFMUstateSize)
    RESOLVE(serialize_fmu_state, fmi2SerializeFMUstate) RESOLVE(deserialize_fmu_state, fmi2DeSerializeFMUstate)
    RESOLVE(get_directional_derivative, fmi2GetDirectionalDerivative)
    RESOLVE(set_real_input_derivatives, fmi2SetRealInputDerivatives)
    RESOLVE(get_real_output_derivatives, fmi2GetRealOutputDerivatives)
    RESOLVE(do_step, fmi2DoStep) RESOLVE(cancel_step, fmi2CancelStep) RESOLVE(get_status, fmi2GetStatus)
    RESOLVE(get_real_status, fmi2GetRealStatus) RESOLVE(get_integer_status, fmi2GetIntegerStatus)
    RESOLVE(get_boolean_status, fmi2GetBooleanStatus) RESOLVE(get_string_status, fmi2GetStringStatus)
    return 1;
}

/* pythonfmu's library keeps its interpreter state in a static std::shared_ptr, which the process's exit
   destroys twice: first its C++ static destructor frees the state, then the library's ELF destructor
   (finalizePythonInterpreter) resets the destroyed pointer, decrementing a count inside the freed block.
   When that block sits in glibc's unsorted bin, the write corrupts the heap and the exit aborts
   ("free(): corrupted unsorted chunks", SIGABRT) after the run's work is done. Exit handlers run in the
   reverse order of their registration, so this one, registered once the library is open, runs before
   its static destructors: it releases the state through the library's own function, and both later
   destructors then find an empty pointer. */
static void (*release_python_state)(void);

static void release_python_state_at_exit(void) {
    release_python_state();
}

static int load_inner(const fmi2CallbackFunctions *cb, fmi2String name) {
    Dl_info self;
    char path[4096];
    const char *slash;
    if (py.lib != NULL)
        return 1;
    if (!load_python(cb, name))
        return 0;
    if (dladdr((void *)&load_inner, &self) == 0 || (slash = strrchr(self.dli_fname, '/')) == NULL) {
        say(cb, name, fmi2Error, "pantohil FMU: cannot tell where its library is");
        return 0;
    }
    snprintf(path, sizeof path, "%.*s/%s", (int)(slash - self.dli_fname), self.dli_fname, PANTOHIL_INNER);
    if ((py.lib = dlopen(path, RTLD_NOW | RTLD_LOCAL)) == NULL) {
        say(cb, name, fmi2Error, "pantohil FMU: cannot open %s (%s)", path, dlerror());
        return 0;
    }
    if (!resolve_all(cb, name, path)) {
        py.lib = NULL;
        return 0;
    }
    *(void **)&release_python_state = dlsym(py.lib, "finalizePythonInterpreter");
    if (release_python_state != NULL)
        atexit(release_python_state_at_exit);
    return 1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

static int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* Any valid `file` URI of a local folder (RFC 8089: file:/p, file:///p, file://localhost/p, with
   percent-encoded octets) as the one form pythonfmu's library reads, "file://" followed by the decoded
   path (it strips "file://" and uses the rest as a path). 0 (and a logged message) for a URI that is
   not a local file URI or does not fit. */
static int local_file_uri(const char *uri, char *out, size_t size, const fmi2CallbackFunctions *cb,
                          fmi2String name) {
    const char *path;
    size_t n = 7;
    if (uri == NULL || strncasecmp(uri, "file:", 5) != 0) {
        say(cb, name, fmi2Error, "fmuResourceLocation %s: not a file URI", uri ? uri : "(null)");
        return 0;
    }
    path = uri + 5;
    if (strncmp(path, "//", 2) == 0) {  /* an authority: empty or localhost */
        path += 2;
        if (strncasecmp(path, "localhost/", 10) == 0)
            path += 9;
        else if (path[0] != '/') {
            say(cb, name, fmi2Error, "fmuResourceLocation %s: a file URI of another host", uri);
            return 0;
        }
    }
    if (path[0] != '/') {
        say(cb, name, fmi2Error, "fmuResourceLocation %s: a file URI needs an absolute path", uri);
        return 0;
    }
    memcpy(out, "file://", 7);
    for (; *path != '\0' && n + 1 < size; n++) {
        if (path[0] == '%' && hex_value(path[1]) >= 0 && hex_value(path[2]) >= 0) {
            out[n] = (char)(hex_value(path[1]) * 16 + hex_value(path[2]));
            path += 3;
        } else {
            out[n] = *path++;
        }
    }
    out[n] = '\0';
    if (*path != '\0' || memchr(out, '\0', n) != NULL) {
        say(cb, name, fmi2Error, "fmuResourceLocation %s: too long, or it encodes a NUL byte", uri);
        return 0;
    }
    return 1;
}

/* Why pythonfmu could not create the FMU's Python class, in one line after its own message: what to install
   when the embedded Python lacks numpy or scipy, else the exception it reported (the last line of its
   message, e.g. ModuleNotFoundError("No module named 'pantohil.models.rig.chain'")). */
static void say_not_created(const fmi2CallbackFunctions *cb, fmi2String name, const char *error) {
    const char *line = strrchr(error, '\n');
    line = line != NULL && line[1] != '\0' ? line + 1 : error;
    if (strstr(error, "No module named 'numpy") != NULL || strstr(error, "No module named 'scipy") != NULL)
        say(cb, name, fmi2Error, "pantohil FMU: its Python class could not be created (see the message before); "
            "the embedded Python needs numpy and scipy (PYTHONHOME=%s, PYTHONPATH=%s)",
            getenv("PYTHONHOME") ? getenv("PYTHONHOME") : "(unset)", getenv("PYTHONPATH") ? getenv("PYTHONPATH") : "(unset)");
    else
        say(cb, name, fmi2Error, "pantohil FMU: its Python class could not be created: %s",
            line[0] != '\0' ? line : "(pythonfmu gave no message)");
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *callbacks, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *inst;
    char location[MESSAGE_SIZE];
    if (!load_inner(callbacks, name) || !local_file_uri(resources, location, sizeof location, callbacks, name))
        return NULL;
    inst = (Instance *)calloc(1, sizeof *inst);
    if (inst == NULL)
        return NULL;
    inst->host = *callbacks;
    inst->wrapped = *callbacks;
    inst->wrapped.logger = relay;
    inst->wrapped.componentEnvironment = inst;
    inst->host_logging = logging;
    inst->name = strdup(name ? name : "");
    inst->inner = py.instantiate(name, type, guid, location, &inst->wrapped, visible, fmi2True);
    if (inst->inner == NULL) {
        say_not_created(callbacks, name, inst->error);
        free(inst->name);
        free(inst);
        return NULL;
    }
    return inst;
}

#define INNER(c) (((Instance *)(c))->inner)

/* pythonfmu reports any exception of the model's Python code as fmi2Fatal. It concerns that instance
   only: the interpreter and the other instances go on, and the instance can be reset or freed, which is
   fmi2Error in FMI 2.0 (sec. 2.1.3); fmi2Fatal is kept for the loader's own failures (no interpreter). */
static fmi2Status error_not_fatal(fmi2Status status) { return status == fmi2Fatal ? fmi2Error : status; }

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL)
        return;
    py.free_instance(inst->inner);
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    ((Instance *)c)->host_logging = on;
    return error_not_fatal(py.set_debug_logging(INNER(c), fmi2True, n, categories));
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    return error_not_fatal(py.setup_experiment(INNER(c), tol_defined, tol, start, stop_defined, stop));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return error_not_fatal(py.enter_initialization_mode(INNER(c))); }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    const fmi2ValueReference vr = PANTOHIL_TIME_STEP_VR;
    fmi2Status status = error_not_fatal(py.exit_initialization_mode(inst->inner));
    if (status <= fmi2Warning && py.get_real(inst->inner, &vr, 1, &inst->time_step_s) > fmi2Warning)
        inst->time_step_s = 0.0;
    return status;
}

/* Steps a master takes to reach its stop time: a step within STEP_ROUNDING of dt is dt (a master's time
   accumulates rounding: OMSimulator asks for 0.99999947 ms after 187.2 s at 1 ms); a remainder below
   STEP_REMAINDER of dt (a stop time that is not a whole number of steps: 1.5e-11 s) is taken with no model
   step, the outputs holding; anything else is refused with fmi2Error and a message naming the step. */
#define STEP_ROUNDING 1e-6
#define STEP_REMAINDER 1e-3

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior) {
    Instance *inst = (Instance *)c;
    double dt = inst->time_step_s;
    if (dt > 0.0 && h >= 0.0 && h < STEP_REMAINDER * dt)
        return fmi2OK;
    if (dt > 0.0 && fabs(h - dt) > STEP_ROUNDING * dt) {
        say(&inst->host, inst->name, fmi2Error, "doStep at t = %.9g s with a communication step of %.9g s: this "
            "FMU takes only its fixed step of %.9g s (parameter time_step; a step within 1e-6 of it is taken as "
            "it, a last step below 1e-3 of it is taken with no model step)", t, h, dt);
        return fmi2Error;
    }
    return error_not_fatal(py.do_step(inst->inner, t, dt, no_set_prior));
}

fmi2Status fmi2Terminate(fmi2Component c) { return error_not_fatal(py.terminate(INNER(c))); }
fmi2Status fmi2Reset(fmi2Component c) { ((Instance *)c)->time_step_s = 0.0; return error_not_fatal(py.reset(INNER(c))); }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    return error_not_fatal(py.get_real(INNER(c), vr, n, v));
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    return error_not_fatal(py.get_integer(INNER(c), vr, n, v));
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    return error_not_fatal(py.get_boolean(INNER(c), vr, n, v));
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    return error_not_fatal(py.get_string(INNER(c), vr, n, v));
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    return error_not_fatal(py.set_real(INNER(c), vr, n, v));
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    return error_not_fatal(py.set_integer(INNER(c), vr, n, v));
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    return error_not_fatal(py.set_boolean(INNER(c), vr, n, v));
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    return error_not_fatal(py.set_string(INNER(c), vr, n, v));
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { return error_not_fatal(py.get_fmu_state(INNER(c), s)); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return error_not_fatal(py.set_fmu_state(INNER(c), s)); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { return error_not_fatal(py.free_fmu_state(INNER(c), s)); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    return error_not_fatal(py.serialized_fmu_state_size(INNER(c), s, size));
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size) {
    return error_not_fatal(py.serialize_fmu_state(INNER(c), s, bytes, size));
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s) {
    return error_not_fatal(py.deserialize_fmu_state(INNER(c), bytes, size, s));
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    return error_not_fatal(py.get_directional_derivative(INNER(c), u, nu, z, nz, dv, dz));
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    return error_not_fatal(py.set_real_input_derivatives(INNER(c), vr, n, order, v));
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    return error_not_fatal(py.get_real_output_derivatives(INNER(c), vr, n, order, v));
}
fmi2Status fmi2CancelStep(fmi2Component c) { return error_not_fatal(py.cancel_step(INNER(c))); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    return error_not_fatal(py.get_status(INNER(c), k, v));
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    return error_not_fatal(py.get_real_status(INNER(c), k, v));
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    return error_not_fatal(py.get_integer_status(INNER(c), k, v));
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    return error_not_fatal(py.get_boolean_status(INNER(c), k, v));
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    return error_not_fatal(py.get_string_status(INNER(c), k, v));
}
