/*
 * FMI 2.0 loader for the project's pythonfmu FMUs: binaries/<platform>/<modelIdentifier>.{so,dll}.
 *
 * pythonfmu 0.7's binary (kept next to this one as <modelIdentifier>_pythonfmu.{so,dll}) embeds CPython
 * but does not link it: it expects the host process to provide the Python C API. A Python host (fmpy,
 * libcosimpy, ecospy) does; a native host does not. This library is what the host loads. Before it loads
 * pythonfmu's binary it makes sure a CPython shared library is loaded with global symbol visibility,
 * searching in this order (the first that loads wins):
 *
 *   0. the host process itself (a Python host, or a libpython the host linked or preloaded);
 *   1. the file named by the environment variable BEARING_FMU_LIBPYTHON (if set, nothing else is tried);
 *   2. the interpreter named by BEARING_FMU_PYTHON, else `python3` on PATH: asked for
 *      sysconfig LIBDIR/INSTSONAME and LIBDIR/LDLIBRARY (its home, sys.base_prefix, is used as the
 *      embedded interpreter's home);
 *   3. the usual names libpython3.14.so.1.0 ... libpython3.9.so.1.0 (then libpython3.X.so) on the
 *      dynamic linker's search path.
 *
 * If none loads, fmi2Instantiate returns NULL after a logger message (category "logStatusError") that
 * lists what was searched and how to point the FMU at a Python. Every other fmi2* call is forwarded.
 *
 * Besides loading Python, it
 *   - gives every native thread that calls the FMU one persistent Python thread state, so pythonfmu's
 *     PyGILState_Ensure/Release per call only takes and drops the GIL instead of creating and deleting a
 *     thread state (and its frame stack) on every call: the cost of a call from a native host;
 *   - initialises the interpreter itself (Py_InitializeEx(0): no signal handlers in the host) on the
 *     thread of the first fmi2Instantiate, when the host has not, and never finalises it: pythonfmu's
 *     worker thread then sees an initialised Python and neither initialises nor finalises it. Finalising
 *     an embedded interpreter at process exit from pythonfmu's worker thread crashed some hosts and can
 *     deadlock others (threading._shutdown waits for the host thread that imported `threading`); the
 *     FMU holds nothing that needs Python-level clean-up, so the process just exits;
 *   - calls pythonfmu's finalizePythonInterpreter() from an exit handler registered after pythonfmu's
 *     binary was loaded, so it runs before pythonfmu's own static destructor and library destructor:
 *     it only drops pythonfmu's state object (whose worker thread has long returned), and pythonfmu's
 *     later double release of that object becomes a no-op. This library pins itself (RTLD_NODELETE), so
 *     the handler runs at process exit, not at dlclose, and the interpreter outlives any reload;
 *   - never passes a NULL category to the host's logger (pythonfmu's own messages go through a wrapper),
 *     and tells the FMU's Python side the host's own callbacks (bearingLoaderHostCallbacks);
 *   - keeps pythonfmu's logging always on (fmi2Instantiate, fmi2SetDebugLogging) and filters by the host's
 *     wish: errors (fmi2Error, fmi2Fatal) always reach the host, e.g. an ImportError of a damaged FMU
 *     that only pythonfmu can report; other messages only with the host's logging on, in its categories;
 *     pythonfmu's repeat of an error the slave already sent directly (bearingLoaderDirectError) is
 *     dropped with logging off (see pass_message);
 *   - returns fmi2Error, not pythonfmu's fmi2Fatal, from a failed fmi2ExitInitializationMode: our slaves
 *     leave the instance intact there (docs/fmu-interface.md, "Errors");
 *   - serves fmi2SetReal of inputs, fmi2DoStep and fmi2GetReal of the force outputs with one Python call
 *     per step when the slave registered a step function (bearingLoaderRegisterStep; "fast path" below),
 *     with the values and statuses of pythonfmu's path;
 *   - does the whole BallBearing doStep in C when the slave registered its kernel (bearingLoaderRegisterKernel;
 *     damping models 0 and 1): the Python step's operations in the same order, the same doubles; its state is
 *     pushed into the slave before any forwarded call, and fmi2Get/SetFMUstate copy it in C ("C step", "FMU
 *     states in C" below); BEARING_FMU_C_STEP=0 at fmi2Instantiate turns it off;
 *   - implements fmi2GetDirectionalDerivative from the FMU's tangent outputs when the build gives it a
 *     table (unknown, known) -> output holding d unknown / d known (see fmu_bearing/native/build.py);
 *     pythonfmu 0.7 does not support that call.
 *
 * Build: fmu_bearing/native/build.py (zig cc; Linux target glibc 2.17).
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif
#include <stdarg.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

#ifdef _WIN32
#include <windows.h>
#define EXPORT __declspec(dllexport)
#ifdef _MSC_VER
#define THREAD_LOCAL __declspec(thread)
#else
#define THREAD_LOCAL __thread
#endif
#define LIB_SUFFIX ".dll"
#else
#include <dlfcn.h>
#include <pthread.h>
#include <unistd.h>
#define EXPORT __attribute__((visibility("default")))
#define THREAD_LOCAL __thread
#ifdef __APPLE__
#define LIB_SUFFIX ".dylib"
#else
#define LIB_SUFFIX ".so"
#endif
#endif

#ifdef LOADER_CONFIG
#include LOADER_CONFIG /* generated by build.py: DD_TABLE, DD_COUNT */
#endif
#ifndef DD_COUNT
#define DD_COUNT 0
#endif

/* ---- FMI 2.0 types (fmi2TypesPlatform.h / fmi2FunctionTypes.h) ------------------------------------ */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* ---- the FMI functions of pythonfmu's binary ------------------------------------------------------ */
#define FMI2_FUNCTIONS(X)                                                                                   \
    X(fmi2Status, SetupExperiment,                                                                          \
      (fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0, fmi2Boolean stopDef, fmi2Real t1),   \
      (c, tolDef, tol, t0, stopDef, t1))                                                                    \
    X(fmi2Status, EnterInitializationMode, (fmi2Component c), (c))                                          \
    X(fmi2Status, GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]),  \
      (c, vr, n, v))                                                                                        \
    X(fmi2Status, GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]),    \
      (c, vr, n, v))                                                                                        \
    X(fmi2Status, SetInteger,                                                                               \
      (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]), (c, vr, n, v))     \
    X(fmi2Status, SetBoolean,                                                                               \
      (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]), (c, vr, n, v))     \
    X(fmi2Status, SetString,                                                                                \
      (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]), (c, vr, n, v))      \
    X(fmi2Status, DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate * s),   \
      (c, b, n, s))                                                                                         \
    X(fmi2Status, SetRealInputDerivatives,                                                                  \
      (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]), \
      (c, vr, n, o, v))                                                                                     \
    X(fmi2Status, GetRealOutputDerivatives,                                                                 \
      (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]),      \
      (c, vr, n, o, v))                                                                                     \
    X(fmi2Status, CancelStep, (fmi2Component c), (c))                                                       \
    X(fmi2Status, GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status * v), (c, k, v))          \
    X(fmi2Status, GetRealStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Real * v), (c, k, v))        \
    X(fmi2Status, GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer * v), (c, k, v))  \
    X(fmi2Status, GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean * v), (c, k, v))  \
    X(fmi2Status, GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String * v), (c, k, v))

/* the functions of the fast path (see "fast path" below): defined one by one, not by FORWARD */
#define FMI2_FAST_FUNCTIONS(X)                                                                              \
    X(fmi2Status, Terminate, (fmi2Component c), (c))                                                        \
    X(fmi2Status, Reset, (fmi2Component c), (c))                                                            \
    X(fmi2Status, GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]),        \
      (c, vr, n, v))                                                                                        \
    X(fmi2Status, GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]),  \
      (c, vr, n, v))                                                                                        \
    X(fmi2Status, SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]),  \
      (c, vr, n, v))                                                                                        \
    X(fmi2Status, DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior), (c, t, h, noSetPrior)) \
    X(fmi2Status, GetFMUstate, (fmi2Component c, fmi2FMUstate * s), (c, s))                                 \
    X(fmi2Status, SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s))                                   \
    X(fmi2Status, FreeFMUstate, (fmi2Component c, fmi2FMUstate * s), (c, s))                                \
    X(fmi2Status, SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t * n), (c, s, n))         \
    X(fmi2Status, SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n),             \
      (c, s, b, n))

typedef fmi2Component (*InstantiateFn)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                       const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef void (*FreeInstanceFn)(fmi2Component);
typedef fmi2Status (*SetDebugLoggingFn)(fmi2Component, fmi2Boolean, size_t, const fmi2String[]);
typedef fmi2Status (*ExitInitializationModeFn)(fmi2Component);
typedef fmi2Status (*GetDirectionalDerivativeFn)(fmi2Component, const fmi2ValueReference[], size_t,
                                                 const fmi2ValueReference[], size_t, const fmi2Real[], fmi2Real[]);

#define DECLARE_POINTER(ret, name, params, args) ret(*name) params;
static struct {
    InstantiateFn Instantiate;
    FreeInstanceFn FreeInstance;
    SetDebugLoggingFn SetDebugLogging;
    ExitInitializationModeFn ExitInitializationMode;
    GetDirectionalDerivativeFn GetDirectionalDerivative;
    void (*finalize)(void);
    FMI2_FUNCTIONS(DECLARE_POINTER)
    FMI2_FAST_FUNCTIONS(DECLARE_POINTER)
} fmi;

/* ---- the few Python C API functions the loader itself calls (stable ABI, 3.9+) -------------------- */
typedef int PyGILState_STATE;
static struct {
    int (*IsInitialized)(void);
    void (*InitializeEx)(int);
    void *(*GILState_GetThisThreadState)(void);
    PyGILState_STATE (*GILState_Ensure)(void);
    void *(*Eval_SaveThread)(void);
    void (*SetPythonHome)(const wchar_t *);
    wchar_t *(*DecodeLocale)(const char *, size_t *);
    /* the fast path (optional: without any of them every call is forwarded) */
    void (*GILState_Release)(PyGILState_STATE);
    void (*IncRef)(void *);
    void (*DecRef)(void *);
    void *(*Float_FromDouble)(double);
    double (*Float_AsDouble)(void *);
    void *(*Tuple_New)(ptrdiff_t);
    int (*Tuple_SetItem)(void *, ptrdiff_t, void *);
    void *(*Tuple_GetItem)(void *, ptrdiff_t);
    ptrdiff_t (*Tuple_Size)(void *);
    void *(*Object_Call)(void *, void *, void *);
    void *(*Object_Vectorcall)(void *, void *const *, size_t, void *);   /* 3.12+ stable ABI; else NULL */
    void *(*Err_Occurred)(void);
    void (*Err_Clear)(void);
    ptrdiff_t (*List_Size)(void *);
    void *None;                                     /* _Py_NoneStruct */
} py;
static int fast_api;  /* 1: every function the fast path needs (but Object_Vectorcall) was found */

#define MAX_CATEGORIES 16
#define FAST_MAX_IN 16
#define FAST_MAX_OUT 32

/* ---- the C step's data (see "C step" below): the slave's constants and state, as doubles ------------ */
#define K_OUTPUTS 10   /* F_x F_y k_xx k_xy k_yy c_xx c_xy c_yy loaded_balls max_ball_load (BearingForce) */
#define K_LIFE 4       /* LifeAccumulator.state(): sum_cubed_inner sum_cubed_outer revolutions time */
typedef struct {
    int n_balls, capacity, life_on;
    double K, half, C, w_inner, w_outer, limit;           /* BallBearing: stiffness ... eccentricity limit */
    double p_e, cube_of_stationary, two_pi, load_angular_velocity;   /* life.py's constants, as Python has them */
    fmi2ValueReference out_vr[K_OUTPUTS], cage_vr, load_vr0;          /* outputs, cage_angle, ball_load_1 */
    double *balls;                      /* n_balls x (cos, sin, cos^2, cos sin, sin^2): BallBearing._balls */
    /* state */
    double cage_angle, out[K_OUTPUTS], life[K_LIFE];
    double *loads;                      /* capacity ball loads (ball_load_1 ...) */
    double *scratch;                    /* this step's loads until the step is accepted */
} Kernel;

/* ---- one instance: pythonfmu's component and the host's callbacks --------------------------------- */
typedef struct {
    fmi2Component inner;                /* pythonfmu's component */
    fmi2CallbackFunctions callbacks;    /* what pythonfmu got: our logger, with this instance as environment */
    fmi2CallbackLogger host_logger;
    fmi2StepFinished host_step_finished;
    fmi2ComponentEnvironment host_env;
    const fmi2CallbackFunctions *host_functions;  /* the host's own struct (FMI: valid until fmi2FreeInstance) */
    char name[128];                     /* instance name, for the loader's own messages */
    int host_logging;                   /* the host's loggingOn / fmi2SetDebugLogging (pythonfmu's is always on) */
    int n_categories;                   /* the host's categories (0: all) */
    char categories[MAX_CATEGORIES][64];
    volatile int direct_error;          /* the slave sent an error to the host directly during this call */
    int in_exit_initialization;         /* inside fmi2ExitInitializationMode: Fatal is reported as Error */
    /* the fast path (see "fast path" below) */
    void *step;                         /* PyObject*: the slave's step(t, h, *inputs), a strong reference */
    void *queue;                        /* PyObject*: the slave's log queue (a list pythonfmu empties), or NULL */
    int n_in, n_out;
    fmi2ValueReference in_vr[FAST_MAX_IN], out_vr[FAST_MAX_OUT];
    int out_index[FAST_MAX_OUT];        /* out_vr[k] is item out_index[k] of what step returns */
    int fast_on;                        /* step registered, initialised, not terminated */
    int in_valid;                       /* in_val mirrors the slave's inputs */
    unsigned in_dirty;                  /* bit i: in_val[i] was set here and not yet passed to the slave */
    int out_valid;                      /* out_val mirrors the slave's outputs out_vr */
    fmi2Real in_val[FAST_MAX_IN], out_val[FAST_MAX_OUT];
    /* the C step (see "C step" below) */
    void *k_load, *k_store;             /* PyObject*: the slave's kernel_load() and kernel_store(values), or NULL */
    int k_retry;                        /* load (again) before the next step: the slave may have changed */
    volatile int slave_error;           /* the slave logged an error during this forwarded call (see after_forward) */
    int k_valid;                        /* the kernel holds the slave's state (spec and state loaded) */
    int k_dirty;                        /* the kernel stepped since the last push: the slave is behind */
    long long k_steps;                  /* steps done in C (tests: bearingLoaderKernelSteps) */
    long long k_states;                 /* FMU states saved in C (tests: bearingLoaderKernelStates) */
    Kernel k;
} Instance;

static void drop_step(Instance *inst);
static void materialise_all(Instance *inst);
static void disown_all(Instance *inst);

/* The live instances, so bearingLoaderHostCallbacks can tell one of ours from any other pointer without
   dereferencing it. */
#define MAX_LIVE 4096
static Instance *live[MAX_LIVE];

static int loaded = 0;           /* 1: pythonfmu's binary and Python are loaded */
static char load_error[4096];    /* why loading failed (reported by every fmi2Instantiate) */
#if defined(__linux__)
__attribute__((tls_model("initial-exec")))  /* no __tls_get_addr call on every FMI call */
#endif
static THREAD_LOCAL int thread_attached;  /* 1: this thread has its persistent Python thread state */
#if defined(__linux__)
__attribute__((tls_model("initial-exec")))
#endif
static THREAD_LOCAL Instance *registering;  /* inside this thread's fmi2Instantiate / fmi2Reset of it */

#ifndef _WIN32
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
#define LOCK() pthread_mutex_lock(&load_lock)
#define UNLOCK() pthread_mutex_unlock(&load_lock)
#else
static SRWLOCK load_lock = SRWLOCK_INIT;
#define LOCK() AcquireSRWLockExclusive(&load_lock)
#define UNLOCK() ReleaseSRWLockExclusive(&load_lock)
#endif

/* ---- small helpers -------------------------------------------------------------------------------- */
static void appendf(char *buf, size_t size, const char *fmt, ...) {
    size_t used = strlen(buf);
    if (used + 1 >= size) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf + used, size - used, fmt, ap);
    va_end(ap);
}

/* Log through the host's logger (if any, else stderr); the text is passed with '%' escaped. */
static void host_log(const fmi2CallbackFunctions *f, fmi2ComponentEnvironment env, fmi2String name,
                     fmi2Status status, fmi2String category, const char *text) {
    size_t n = strlen(text), extra = 0, i, j;
    for (i = 0; i < n; i++) extra += text[i] == '%';
    char *escaped = (char *)malloc(n + extra + 1);
    if (escaped == NULL) return;
    for (i = 0, j = 0; i < n; i++) {
        escaped[j++] = text[i];
        if (text[i] == '%') escaped[j++] = '%';
    }
    escaped[j] = '\0';
    if (f != NULL && f->logger != NULL)
        f->logger(env, name ? name : "", status, category, escaped);
    else
        fprintf(stderr, "%s [%s]: %s\n", name ? name : "", category, text);
    free(escaped);
}

static const char *status_category(fmi2Status status) {
    switch (status) {
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    case fmi2Fatal: return "logStatusFatal";
    case fmi2Pending: return "logStatusPending";
    default: return "logAll";
    }
}

/* Whether a message pythonfmu hands the loader goes on to the host. pythonfmu 0.7 forwards messages only
   with logging on, so the loader always instantiates it with loggingOn = fmi2True (else a failure before
   the slave's code runs, e.g. a module missing from a damaged FMU, would never be reported) and filters
   here by the host's wish: errors (fmi2Error, fmi2Fatal) always, other messages only with the host's
   logging on and, if it named categories in fmi2SetDebugLogging, in one of them. pythonfmu's own report of
   an exception (category NULL) is dropped with the host's logging off when the slave already sent the
   error to the host directly during this call (fmu_bearing.slaves.HostLogger -> bearingLoaderDirectError):
   the host then gets the cause once, as before with logging off. */
static int pass_message(const Instance *inst, fmi2Status status, fmi2String category) {
    if (status >= fmi2Error)
        return inst->host_logging || !inst->direct_error || (category != NULL && category[0] != '\0');
    if (!inst->host_logging) return 0;
    if (inst->n_categories == 0) return 1;
    const char *cat = (category == NULL || category[0] == '\0') ? status_category(status) : category;
    for (int i = 0; i < inst->n_categories; i++)
        if (strcmp(inst->categories[i], cat) == 0) return 1;
    return 0;
}

static void set_categories(Instance *inst, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    inst->host_logging = on != 0;
    inst->n_categories = 0;
    if (!on || categories == NULL || n > MAX_CATEGORIES) return;  /* too many to keep: all categories */
    for (size_t i = 0; i < n; i++)
        if (categories[i] != NULL)
            snprintf(inst->categories[inst->n_categories++], sizeof inst->categories[0], "%s", categories[i]);
}

/* The logger pythonfmu calls: format, then pass to the host's logger with a category that is never NULL. */
static void forward_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                           fmi2String message, ...) {
    Instance *inst = (Instance *)env;
    char stack[1024], *text = stack;
    va_list ap;
    va_start(ap, message);
    int n = vsnprintf(stack, sizeof stack, message ? message : "", ap);
    va_end(ap);
    if (n >= (int)sizeof stack && (text = (char *)malloc((size_t)n + 1)) != NULL) {
        va_start(ap, message);
        vsnprintf(text, (size_t)n + 1, message, ap);
        va_end(ap);
    }
    if (text == NULL) text = stack;
    if (inst != NULL && status >= fmi2Error) inst->slave_error = 1;
    if (inst != NULL && inst->in_exit_initialization && status == fmi2Fatal)
        status = fmi2Error;  /* the message goes with the status the call returns (fmi2ExitInitializationMode) */
    if (inst != NULL && !pass_message(inst, status, category)) {
        if (text != stack) free(text);
        return;
    }
    if (category == NULL || category[0] == '\0') category = status_category(status);
    if (inst != NULL && inst->host_logger != NULL) {
        fmi2CallbackFunctions f = {inst->host_logger, NULL, NULL, NULL, NULL};
        host_log(&f, inst->host_env, name, status, category, text);
    } else {
        host_log(NULL, NULL, name, status, category, text);
    }
    if (text != stack) free(text);
}

static void forward_step_finished(fmi2ComponentEnvironment env, fmi2Status status) {
    Instance *inst = (Instance *)env;
    if (inst != NULL && inst->host_step_finished != NULL) inst->host_step_finished(inst->host_env, status);
}

/* Give the calling native thread a persistent Python thread state (see the header comment). */
static void attach_thread(void) {
    if (thread_attached || py.IsInitialized == NULL || !py.IsInitialized()) return;
    if (py.GILState_GetThisThreadState() == NULL) {
        py.GILState_Ensure();   /* creates this thread's state (count 1) and takes the GIL */
        py.Eval_SaveThread();   /* drops the GIL, keeps the state: later Ensure/Release only switch the GIL */
    }
    thread_attached = 1;
}

/* ---- platform layer: libraries, own path, exit handler -------------------------------------------- */
#ifndef _WIN32
typedef void *Library;
static Library lib_open_global(const char *path) { return dlopen(path, RTLD_NOW | RTLD_GLOBAL); }
static Library lib_open_local(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *lib_sym(Library lib, const char *name) { return dlsym(lib, name); }
static void *process_sym(const char *name) { return dlsym(RTLD_DEFAULT, name); }
static const char *lib_error(void) {
    const char *e = dlerror();
    return e ? e : "unknown error";
}
static int own_path(char *buf, size_t size) {
    Dl_info info;
    if (!dladdr((void *)&own_path, &info) || info.dli_fname == NULL) return 0;
    snprintf(buf, size, "%s", info.dli_fname);
    return 1;
}
static void pin_self(const char *path) {
    /* Never unloaded: the exit handler below then runs at process exit, and a host that unloads and
       reloads the FMU keeps the one interpreter instead of finalising and re-initialising it. */
    dlopen(path, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
}
#else
typedef HMODULE Library;
static Library lib_open_global(const char *path) { return LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH); }
static Library lib_open_local(const char *path) { return LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH); }
static void *lib_sym(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
static void *process_sym(const char *name) {
    /* the python3X.dll a Python host (or an earlier load) has in the process */
    char dll[32];
    int minor;
    for (minor = 14; minor >= 9; minor--) {
        snprintf(dll, sizeof dll, "python3%d.dll", minor);
        HMODULE h = GetModuleHandleA(dll);
        if (h != NULL) return (void *)GetProcAddress(h, name);
    }
    return NULL;
}
static const char *lib_error(void) {
    static THREAD_LOCAL char msg[64];
    snprintf(msg, sizeof msg, "Windows error %lu", (unsigned long)GetLastError());
    return msg;
}
static int own_path(char *buf, size_t size) {
    HMODULE self = NULL;
    if (!GetModuleHandleExA(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCSTR)&own_path, &self))
        return 0;
    DWORD n = GetModuleFileNameA(self, buf, (DWORD)size);
    return n > 0 && n < size;
}
static void pin_self(const char *path) {
    HMODULE self;
    GetModuleHandleExA(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_PIN, (LPCSTR)&own_path, &self);
    (void)path;
}
#endif

static void finalize_at_exit(void) {
    if (fmi.finalize != NULL) {
        fmi.finalize();  /* pythonfmu: drop its state object once, now (it finalises nothing: see above) */
        fmi.finalize = NULL;
    }
}

/* ---- finding Python ------------------------------------------------------------------------------- */
#ifndef _WIN32
static wchar_t python_home[4096];
#endif

static int resolve_python(Library lib) {
#define RESOLVE(field, name)                                                                   \
    py.field = (lib != NULL) ? lib_sym(lib, name) : process_sym(name);
    RESOLVE(IsInitialized, "Py_IsInitialized")
    RESOLVE(InitializeEx, "Py_InitializeEx")
    RESOLVE(GILState_GetThisThreadState, "PyGILState_GetThisThreadState")
    RESOLVE(GILState_Ensure, "PyGILState_Ensure")
    RESOLVE(Eval_SaveThread, "PyEval_SaveThread")
    RESOLVE(SetPythonHome, "Py_SetPythonHome")
    RESOLVE(DecodeLocale, "Py_DecodeLocale")
    RESOLVE(GILState_Release, "PyGILState_Release")
    RESOLVE(IncRef, "Py_IncRef")
    RESOLVE(DecRef, "Py_DecRef")
    RESOLVE(Float_FromDouble, "PyFloat_FromDouble")
    RESOLVE(Float_AsDouble, "PyFloat_AsDouble")
    RESOLVE(Tuple_New, "PyTuple_New")
    RESOLVE(Tuple_SetItem, "PyTuple_SetItem")
    RESOLVE(Tuple_GetItem, "PyTuple_GetItem")
    RESOLVE(Tuple_Size, "PyTuple_Size")
    RESOLVE(Object_Call, "PyObject_Call")
    RESOLVE(Object_Vectorcall, "PyObject_Vectorcall")
    RESOLVE(Err_Occurred, "PyErr_Occurred")
    RESOLVE(Err_Clear, "PyErr_Clear")
    RESOLVE(List_Size, "PyList_Size")
    RESOLVE(None, "_Py_NoneStruct")
#undef RESOLVE
    fast_api = py.GILState_Release && py.IncRef && py.DecRef && py.Float_FromDouble && py.Float_AsDouble &&
               py.Tuple_New && py.Tuple_SetItem && py.Tuple_GetItem && py.Tuple_Size && py.Object_Call &&
               py.Err_Occurred && py.Err_Clear && py.List_Size && py.None;
    return py.IsInitialized && py.InitializeEx && py.GILState_GetThisThreadState && py.GILState_Ensure &&
           py.Eval_SaveThread;
}

static int try_library(const char *path, char *report, size_t size) {
    Library lib = lib_open_global(path);
    if (lib == NULL) {
        appendf(report, size, "\n  %s: %s", path, lib_error());
        return 0;
    }
    if (!resolve_python(lib)) {
        appendf(report, size, "\n  %s: loaded, but it is not a CPython library (no Py_IsInitialized)", path);
        return 0;
    }
#ifdef _WIN32
    {   /* pythonfmu's DLL imports python3.dll (the stable ABI forwarder): load the one next to python3X.dll */
        char dll[MAX_PATH];
        DWORD n = GetModuleFileNameA(lib, dll, MAX_PATH);
        char *slash = n > 0 && n < MAX_PATH ? strrchr(dll, '\\') : NULL;
        if (slash != NULL && (size_t)(slash - dll) + 13 < MAX_PATH) {
            strcpy(slash + 1, "python3.dll");
            LoadLibraryExA(dll, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
        }
    }
#endif
    return 1;
}

#ifndef _WIN32
/* Ask an interpreter where its shared library is: lines "home", then candidate paths. */
static int try_interpreter(const char *python, char *report, size_t size) {
    char command[1024], line[4096], home[4096] = "";
    int found = 0, lines = 0, own_library = 0;
    static const char script[] =
        "import os, sys, sysconfig as s; v = s.get_config_var; d = v('LIBDIR') or ''; print(sys.base_prefix); "
        "[print(os.path.join(d, n)) for n in (v('INSTSONAME'), v('LDLIBRARY')) if n and '" LIB_SUFFIX "' in n]";
    snprintf(command, sizeof command, "'%s' -E -s -c \"%s\" 2>/dev/null </dev/null", python, script);
    FILE *pipe = popen(command, "r");
    if (pipe == NULL) {
        appendf(report, size, "\n  %s: could not run it", python);
        return 0;
    }
    while (fgets(line, sizeof line, pipe) != NULL) {
        line[strcspn(line, "\r\n")] = '\0';
        if (lines++ == 0) {
            snprintf(home, sizeof home, "%s", line);
            continue;
        }
        if (!found && line[0] != '\0') {
            if (access(line, R_OK) == 0) {
                found = own_library = try_library(line, report, size);
            } else {
                const char *base = strrchr(line, '/');
                appendf(report, size, "\n  %s (from %s): no such file", line, python);
                if (base != NULL) found = try_library(base + 1, report, size);
            }
        }
    }
    int status = pclose(pipe);
    if (lines == 0)
        appendf(report, size, "\n  %s: not found or failed (exit status %d)", python, status);
    else if (lines == 1 && !found)
        appendf(report, size, "\n  %s: has no shared libpython (built without --enable-shared)", python);
    /* its home only with its own library (one found by name may belong to another installation) */
    if (own_library && home[0] != '\0' && py.SetPythonHome != NULL && py.DecodeLocale != NULL && !py.IsInitialized()) {
        wchar_t *w = py.DecodeLocale(home, NULL);
        if (w != NULL) {
            wcsncpy(python_home, w, sizeof python_home / sizeof python_home[0] - 1);
            py.SetPythonHome(python_home);  /* the interpreter's own prefix, also for relocated builds */
        }
    }
    return found;
}
#endif

static int find_python(char *report, size_t size) {
    if (resolve_python(NULL)) return 1;  /* 0. the host process has Python */
    const char *env = getenv("BEARING_FMU_LIBPYTHON");
    appendf(report, size, "searched (the first that loads is used):");
    if (env != NULL && env[0] != '\0') {
        appendf(report, size, "\n  BEARING_FMU_LIBPYTHON=%s", env);
        return try_library(env, report, size);
    }
    appendf(report, size, "\n  BEARING_FMU_LIBPYTHON: not set");
#ifndef _WIN32
    const char *python = getenv("BEARING_FMU_PYTHON");
    if (python == NULL || python[0] == '\0') python = "python3";
    if (strchr(python, '\'') == NULL && try_interpreter(python, report, size)) return 1;
#endif
    int minor;
    char name[64];
    for (minor = 14; minor >= 9; minor--) {
#ifdef _WIN32
        snprintf(name, sizeof name, "python3%d.dll", minor);
#elif defined(__APPLE__)
        snprintf(name, sizeof name, "libpython3.%d.dylib", minor);
#else
        snprintf(name, sizeof name, "libpython3.%d.so.1.0", minor);
#endif
        if (try_library(name, report, size)) return 1;
    }
#if !defined(_WIN32) && !defined(__APPLE__)
    for (minor = 14; minor >= 9; minor--) {
        snprintf(name, sizeof name, "libpython3.%d.so", minor);
        if (try_library(name, report, size)) return 1;
    }
#endif
    return 0;
}

/* Load Python, then pythonfmu's binary; 1 on success, else 0 with load_error set. */
static int ensure_loaded(void) {
    char self[4096], target[4200], report[3072] = "";
    if (loaded) return 1;
    if (load_error[0] != '\0') return 0;
    if (!own_path(self, sizeof self)) {
        snprintf(load_error, sizeof load_error, "the FMU's loader could not find its own file");
        return 0;
    }
    if (!find_python(report, sizeof report)) {
        snprintf(load_error, sizeof load_error,
                 "no usable CPython shared library (3.9 or later) was found; %s\n"
                 "Point the FMU at one with BEARING_FMU_LIBPYTHON=/path/to/libpython3.X" LIB_SUFFIX
                 "%s, or put a python3 that has one (built with --enable-shared; Debian/Ubuntu: the libpython3.X "
                 "package) first on PATH (or name it with BEARING_FMU_PYTHON=/path/to/python3).",
                 report,
#ifdef _WIN32
                 ""
#else
                 ".1.0"
#endif
        );
        return 0;
    }
    /* <dir>/<modelIdentifier>.so -> <dir>/<modelIdentifier>_pythonfmu.so */
    size_t n = strlen(self), suffix = strlen(LIB_SUFFIX);
    if (n > suffix && strcmp(self + n - suffix, LIB_SUFFIX) == 0) n -= suffix;
    snprintf(target, sizeof target, "%.*s_pythonfmu%s", (int)n, self, LIB_SUFFIX);
    Library lib = lib_open_local(target);
    if (lib == NULL) {
        snprintf(load_error, sizeof load_error, "cannot load pythonfmu's binary %s: %s", target, lib_error());
        return 0;
    }
    fmi.Instantiate = (InstantiateFn)lib_sym(lib, "fmi2Instantiate");
    fmi.FreeInstance = (FreeInstanceFn)lib_sym(lib, "fmi2FreeInstance");
    fmi.SetDebugLogging = (SetDebugLoggingFn)lib_sym(lib, "fmi2SetDebugLogging");
    fmi.ExitInitializationMode = (ExitInitializationModeFn)lib_sym(lib, "fmi2ExitInitializationMode");
    fmi.GetDirectionalDerivative = (GetDirectionalDerivativeFn)lib_sym(lib, "fmi2GetDirectionalDerivative");
#define RESOLVE_FMI(ret, name, params, args) fmi.name = (ret(*) params)lib_sym(lib, "fmi2" #name);
    FMI2_FUNCTIONS(RESOLVE_FMI)
    FMI2_FAST_FUNCTIONS(RESOLVE_FMI)
#undef RESOLVE_FMI
    if (fmi.Instantiate == NULL || fmi.FreeInstance == NULL || fmi.DoStep == NULL || fmi.SetDebugLogging == NULL ||
        fmi.ExitInitializationMode == NULL) {
        snprintf(load_error, sizeof load_error, "%s does not export the FMI 2.0 functions", target);
        return 0;
    }
    fmi.finalize = (void (*)(void))lib_sym(lib, "finalizePythonInterpreter");
    if (!py.IsInitialized()) {
        /* Ours, on this thread; it stays initialised until the process ends (see the header comment). */
        py.InitializeEx(0);
        py.Eval_SaveThread();  /* drop the GIL; this thread keeps the main thread state */
    }
    pin_self(self);
    atexit(finalize_at_exit);  /* registered after pythonfmu's static destructors: runs before them */
    loaded = 1;
    return 1;
}

static void remember(Instance *inst, int add) {
    LOCK();
    for (int i = 0; i < MAX_LIVE; i++) {
        if (add ? live[i] == NULL : live[i] == inst) {
            live[i] = add ? inst : NULL;
            break;
        }
    }
    UNLOCK();
}

/* For the FMU's Python side (fmu_bearing.slaves.HostLogger): the host's own callback functions behind the
   environment pythonfmu was given (one of this loader's instances), so the slave can send an error to the
   host with logging off and recognise the host's logger; NULL for any other pointer. */
EXPORT const fmi2CallbackFunctions *bearingLoaderHostCallbacks(const void *env) {
    const fmi2CallbackFunctions *found = NULL;
    LOCK();
    for (int i = 0; i < MAX_LIVE && found == NULL; i++)
        if (env != NULL && live[i] == (const Instance *)env) found = live[i]->host_functions;
    UNLOCK();
    return found;
}

/* For HostLogger: the slave has just sent an error to the host directly (see pass_message). */
EXPORT void bearingLoaderDirectError(void *env) {
    LOCK();
    for (int i = 0; i < MAX_LIVE; i++)
        if (env != NULL && live[i] == (Instance *)env) {
            live[i]->direct_error = 1;
            live[i]->slave_error = 1;
            break;
        }
    UNLOCK();
}

/* ---- exported FMI 2.0 functions ------------------------------------------------------------------- */
EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type type, fmi2String guid,
                                     fmi2String resourceLocation, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn) {
    LOCK();
    int ok = ensure_loaded();
    UNLOCK();
    if (!ok) {
        char message[sizeof load_error + 64];
        snprintf(message, sizeof message, "fmi2Instantiate: %s", load_error);
        host_log(functions, functions ? functions->componentEnvironment : NULL, instanceName, fmi2Error,
                 "logStatusError", message);
        return NULL;
    }
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    if (inst == NULL) return NULL;
    if (functions != NULL) {
        inst->callbacks = *functions;
        inst->host_logger = functions->logger;
        inst->host_step_finished = functions->stepFinished;
        inst->host_env = functions->componentEnvironment;
        inst->host_functions = functions;
    }
    inst->callbacks.logger = forward_logger;
    inst->callbacks.stepFinished = functions && functions->stepFinished ? forward_step_finished : NULL;
    inst->callbacks.componentEnvironment = inst;
    snprintf(inst->name, sizeof inst->name, "%s", instanceName ? instanceName : "");
    inst->host_logging = loggingOn != 0;
    attach_thread();
    remember(inst, 1);
    /* pythonfmu's logging always on: the loader filters (pass_message) */
    registering = inst;         /* the slave's __init__ may register its step (bearingLoaderRegisterStep) */
    inst->inner = fmi.Instantiate(instanceName, type, guid, resourceLocation, &inst->callbacks, visible, 1);
    registering = NULL;
    if (inst->inner == NULL) {
        drop_step(inst);
        remember(inst, 0);
        free(inst);
        return NULL;
    }
    return inst;
}

EXPORT void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return;
    attach_thread();
    materialise_all(inst);      /* states saved in C become pythonfmu's before the slave goes */
    disown_all(inst);
    const char *counts = getenv("BEARING_FMU_C_STEP_COUNTS");   /* tests: a master run's C steps, per instance */
    if (counts != NULL && counts[0] != '\0') {
        FILE *file = fopen(counts, "a");
        if (file != NULL) {
            fprintf(file, "%lld\n", inst->k_steps);
            fclose(file);
        }
    }
    drop_step(inst);            /* before pythonfmu releases the slave: the callable holds it */
    fmi.FreeInstance(inst->inner);
    remember(inst, 0);
    free(inst);
}

/* ---- fast path ------------------------------------------------------------------------------------
 * pythonfmu 0.7 costs several microseconds per call (a Python list per call, PyObject_CallMethod with a
 * format string, four Py_BuildValue per call to empty its log queue, a Python frame per get/set). A slave
 * can hand the loader one Python callable at instantiation (bearingLoaderRegisterStep, from its __init__):
 * step(t, h, *inputs) sets the inputs, does the step and returns a tuple that holds the outputs (None when
 * the step is refused). Once the instance is initialised (a successful fmi2ExitInitializationMode):
 *   - fmi2SetReal of inputs only stores the values here (in_val, marked dirty);
 *   - fmi2DoStep makes one call of step with the current inputs and keeps the outputs it returns;
 *   - fmi2GetReal of inputs and of those outputs is answered from here.
 * Everything else is forwarded to pythonfmu as before, after the stored inputs were passed on to the slave
 * (one fmi2SetReal of the dirty ones): so every call sees the same slave as without the fast path. Calls
 * that may change inputs or outputs (any set, set state, setup, terminate, reset ...) also drop the copies;
 * reads (get, get/serialize state) keep them. fmi2Terminate, fmi2Reset and fmi2FreeInstance switch the
 * fast path off (and drop the callable: fmi2Reset's new slave registers again). Hosts that load
 * pythonfmu's binary without this loader, and slaves that do not register, use pythonfmu's path. */

/* For the FMU's Python side (called with the GIL held, ctypes.PyDLL): register the slave being
   instantiated on this thread. ``step`` is called as step(t, h, in_1 ... in_n) with n = n_in floats in
   the order of in_vr; it returns None (step refused: fmi2Discard) or a tuple whose item out_index[k] is
   the value of out_vr[k] after the step. ``queue`` (or NULL) is the list pythonfmu takes the slave's
   log messages from at the end of each call (pythonfmu's Fmi2Slave.log_queue): when it is not empty
   after a step, the loader has pythonfmu send them, as its fmi2DoStep would. 1: registered; 0: not (no
   instance is being instantiated on this thread, or the Python library lacks a function the fast path
   needs): the slave is used through pythonfmu as before. */
EXPORT int bearingLoaderRegisterStep(void *step, void *queue, const fmi2ValueReference *in_vr, int n_in,
                                     const fmi2ValueReference *out_vr, const int *out_index, int n_out) {
    Instance *inst = registering;
    if (inst == NULL || step == NULL || !fast_api || in_vr == NULL || n_in < 1 || n_in > FAST_MAX_IN ||
        n_out < 0 || n_out > FAST_MAX_OUT || (n_out > 0 && (out_vr == NULL || out_index == NULL)))
        return 0;
    for (int k = 0; k < n_out; k++)
        if (out_index[k] < 0) return 0;
    if (queue == py.None) queue = NULL;
    py.IncRef(step);
    if (queue != NULL) py.IncRef(queue);
    if (inst->step != NULL) py.DecRef(inst->step);
    if (inst->queue != NULL) py.DecRef(inst->queue);
    inst->step = step;
    inst->queue = queue;
    inst->n_in = n_in;
    inst->n_out = n_out;
    memcpy(inst->in_vr, in_vr, (size_t)n_in * sizeof in_vr[0]);
    if (n_out > 0) {
        memcpy(inst->out_vr, out_vr, (size_t)n_out * sizeof out_vr[0]);
        memcpy(inst->out_index, out_index, (size_t)n_out * sizeof out_index[0]);
    }
    inst->fast_on = inst->in_valid = inst->out_valid = 0;
    inst->in_dirty = 0;
    return 1;
}

/* For the test and benchmark counters below: field ``which`` (0 fast_on, 1 k_steps, 2 k_states) of ``c`` if it
   is one of this loader's live instances, else ``missing``. */
static long long live_counter(const void *c, int which, long long missing) {
    long long n = missing;
    LOCK();
    for (int i = 0; i < MAX_LIVE; i++)
        if (c != NULL && live[i] == (const Instance *)c) {
            n = which == 0 ? live[i]->fast_on : which == 1 ? live[i]->k_steps : live[i]->k_states;
            break;
        }
    UNLOCK();
    return n;
}

/* For tests: 1 if the fast path serves ``c`` (one of this loader's live instances) now, else 0. */
EXPORT int bearingLoaderFastPathOn(const void *c) { return (int)live_counter(c, 0, 0); }

/* Switch the fast path off and release the callable (takes the GIL). */
static void drop_step(Instance *inst) {
    inst->fast_on = inst->in_valid = inst->out_valid = 0;
    inst->in_dirty = 0;
    inst->k_valid = inst->k_dirty = inst->k_retry = 0;   /* the kernel's state dies with the slave */
    if (inst->step != NULL || inst->k_load != NULL) {
        PyGILState_STATE g = py.GILState_Ensure();
        LOCK();   /* k_store: materialise (another thread, GIL held) takes its own reference under LOCK */
        void *step = inst->step, *queue = inst->queue, *load = inst->k_load, *store = inst->k_store;
        inst->step = inst->queue = inst->k_load = inst->k_store = NULL;
        UNLOCK();
        if (step != NULL) py.DecRef(step);
        if (queue != NULL) py.DecRef(queue);
        if (load != NULL) py.DecRef(load);
        if (store != NULL) py.DecRef(store);
        py.GILState_Release(g);
    }
    free(inst->k.balls);
    free(inst->k.loads);
    free(inst->k.scratch);
    inst->k.balls = inst->k.loads = inst->k.scratch = NULL;
    inst->k.n_balls = inst->k.capacity = 0;
}

/* ---- C step ---------------------------------------------------------------------------------------
 * The BallBearing slave's whole doStep in C, for the configurations it covers (damping_model 0 or 1; the
 * oil-film model keeps the Python step). The slave registers two callables at instantiation
 * (bearingLoaderRegisterKernel, from BallBearing.__init__ in fmu_bearing/slaves/ball_bearing_fmu.py):
 *   kernel_load()         -> None (not this configuration, not initialised, terminated, an error pending:
 *                            the Python step) or a flat tuple of numbers: the constants BallBearing
 *                            precomputed (its doubles, not recomputed here), the life constants and the state
 *                            (cage angle, outputs, life sums, ball loads); layout in _kernel_load;
 *   kernel_store(values)  pushes the kernel's state back into the slave: inputs, cage angle, the 10
 *                            BearingForce outputs, life sums, ball loads.
 * Once loaded, fmi2DoStep runs kernel_step below: the operations of BallBearing.advance_cage,
 * BallBearing.evaluate and LifeAccumulator.add (fmu_bearing/ball_bearing.py, fmu_bearing/life.py) in the
 * same order, with the same libm functions CPython's math module and float ** call (cos, sin, sqrt, pow;
 * built with -ffp-contract=off: no fused multiply-add), so every result is the same double as the Python
 * step's. Anything unusual -- a non-finite input, |e| not clearly inside the eccentricity limit (Python's
 * math.hypot is not libm's hypot), a step size not >= 0, a non-finite result or pow overflow -- is not
 * decided here: the state is pushed and the Python step runs (its refusal, message and status exactly as
 * without the kernel), and the kernel reloads before its next step. Before any call is forwarded to
 * pythonfmu the kernel's state is pushed (before_forward); a forwarded call that may change the slave
 * (set, set state, setup, terminate, reset ...) makes the kernel reload before its next step. fmi2GetReal of
 * the outputs the step computes (F_x ... max_ball_load, cage_angle, ball_load_i) and fmi2GetInteger of
 * loaded_balls are answered from the kernel. BEARING_FMU_C_STEP=0 in the environment at fmi2Instantiate
 * turns the kernel off for that instance (the Python step, through the fast path). */

/* For the FMU's Python side (GIL held, ctypes.PyDLL): register the kernel callables of the slave being
   instantiated on this thread (after bearingLoaderRegisterStep). 1: registered; 0: not (no fast path, the
   inputs are not the six joint inputs, or BEARING_FMU_C_STEP=0). */
EXPORT int bearingLoaderRegisterKernel(void *load, void *store) {
#if !defined(__linux__) || !defined(__GLIBC__)
    /* Only where it is tested bit for bit against CPython (glibc's libm, which CPython calls too). The Windows
       loader is cross-built against mingw-w64, whose pow/cos/sin need not be the UCRT's that python.exe calls:
       the Python step there. */
    (void)load;
    (void)store;
    return 0;
#else
    Instance *inst = registering;
    const char *env = getenv("BEARING_FMU_C_STEP");
    if (inst == NULL || inst->step == NULL || load == NULL || store == NULL || load == py.None ||
        store == py.None || inst->n_in != 6 || (env != NULL && strcmp(env, "0") == 0))
        return 0;
    py.IncRef(load);
    py.IncRef(store);
    LOCK();   /* (GIL held: the order GIL -> LOCK) */
    void *old_load = inst->k_load, *old_store = inst->k_store;
    inst->k_load = load;
    inst->k_store = store;
    UNLOCK();
    if (old_load != NULL) py.DecRef(old_load);
    if (old_store != NULL) py.DecRef(old_store);
    inst->k_valid = inst->k_dirty = 0;
    inst->k_retry = 1;
    return 1;
#endif
}

/* For tests and benchmarks: the number of steps ``c`` (one of this loader's live instances) did in C. */
EXPORT long long bearingLoaderKernelSteps(const void *c) { return live_counter(c, 1, -1); }

/* callable(arg) or callable() (arg NULL); a new reference or NULL (GIL held) */
static void *call_python(void *callable, void *arg) {
    void *result = NULL, *tuple = py.Tuple_New(arg != NULL ? 1 : 0);
    if (tuple == NULL) return NULL;
    if (arg != NULL) {
        py.IncRef(arg);   /* PyTuple_SetItem steals one reference */
        py.Tuple_SetItem(tuple, 0, arg);
    }
    result = py.Object_Call(callable, tuple, NULL);
    py.DecRef(tuple);
    return result;
}

#define K_HEADER 25     /* n_balls capacity life_on K half C w_inner w_outer limit p_e cube two_pi load_w
                           out_vr[10] cage_vr load_vr0 */
#define K_STATE (1 + K_OUTPUTS + K_LIFE)

/* Load the slave's constants and state (kernel_load); 1: the kernel owns the step now, 0: Python step. */
static int kernel_load(Instance *inst) {
    Kernel *k = &inst->k;
    int ok = 0, i;
    PyGILState_STATE g = py.GILState_Ensure();
    void *r = call_python(inst->k_load, NULL);
    if (r != NULL && r != py.None) {
        ptrdiff_t size = py.Tuple_Size(r);
#define ITEM(j) py.Float_AsDouble(py.Tuple_GetItem(r, (j)))
        double n = size >= K_HEADER ? ITEM(0) : 0.0, cap = size >= K_HEADER ? ITEM(1) : 0.0;
        if (py.Err_Occurred() == NULL && n >= 1.0 && cap >= n && cap <= 1e6 && n == (int)n && cap == (int)cap &&
            size == K_HEADER + K_STATE + (ptrdiff_t)cap + 5 * (ptrdiff_t)n) {
            int nb = (int)n, nc = (int)cap;
            double *balls = (double *)realloc(k->balls, (size_t)nb * 5 * sizeof(double));
            if (balls != NULL) k->balls = balls;
            double *loads = balls ? (double *)realloc(k->loads, (size_t)nc * sizeof(double)) : NULL;
            if (loads != NULL) k->loads = loads;
            double *scratch = loads ? (double *)realloc(k->scratch, (size_t)nc * sizeof(double)) : NULL;
            if (scratch != NULL) k->scratch = scratch;
            if (scratch != NULL) {
                k->n_balls = nb;
                k->capacity = nc;
                k->life_on = ITEM(2) != 0.0;
                k->K = ITEM(3);
                k->half = ITEM(4);
                k->C = ITEM(5);
                k->w_inner = ITEM(6);
                k->w_outer = ITEM(7);
                k->limit = ITEM(8);
                k->p_e = ITEM(9);
                k->cube_of_stationary = ITEM(10);
                k->two_pi = ITEM(11);
                k->load_angular_velocity = ITEM(12);
                for (i = 0; i < K_OUTPUTS; i++) k->out_vr[i] = (fmi2ValueReference)ITEM(13 + i);
                k->cage_vr = (fmi2ValueReference)ITEM(13 + K_OUTPUTS);
                k->load_vr0 = (fmi2ValueReference)ITEM(14 + K_OUTPUTS);
                k->cage_angle = ITEM(K_HEADER);
                for (i = 0; i < K_OUTPUTS; i++) k->out[i] = ITEM(K_HEADER + 1 + i);
                for (i = 0; i < K_LIFE; i++) k->life[i] = ITEM(K_HEADER + 1 + K_OUTPUTS + i);
                for (i = 0; i < nc; i++) k->loads[i] = ITEM(K_HEADER + K_STATE + i);
                for (i = 0; i < 5 * nb; i++) k->balls[i] = ITEM(K_HEADER + K_STATE + nc + i);
                ok = py.Err_Occurred() == NULL;
            }
        }
#undef ITEM
    }
    if (py.Err_Occurred() != NULL) py.Err_Clear();
    if (r != NULL) py.DecRef(r);
    py.GILState_Release(g);
    return ok;
}

/* The tuple kernel_store takes: inputs, cage angle, outputs, life sums, ball loads (GIL held); NULL on failure */
static void *values_tuple(const double *in, double cage_angle, const double *out, const double *life,
                          const double *loads, int capacity) {
    int n = 6 + K_STATE + capacity, i, j = 0, ok = 1;
    void *tuple = py.Tuple_New(n);
    if (tuple == NULL) return NULL;
#define PUT(x)                                                  \
    do {                                                        \
        void *item_ = py.Float_FromDouble(x);                   \
        if (item_ == NULL) ok = 0; else py.Tuple_SetItem(tuple, j, item_); \
        j++;                                                    \
    } while (0)
    for (i = 0; i < 6; i++) PUT(in[i]);
    PUT(cage_angle);
    for (i = 0; i < K_OUTPUTS; i++) PUT(out[i]);
    for (i = 0; i < K_LIFE; i++) PUT(life[i]);
    for (i = 0; i < capacity; i++) PUT(loads[i]);
#undef PUT
    if (!ok) {
        py.DecRef(tuple);
        return NULL;
    }
    return tuple;
}

/* kernel_store(inputs, cage angle, outputs, life sums, ball loads): 1 on success (takes the GIL) */
static int store_values(Instance *inst, const double *in, double cage_angle, const double *out, const double *life,
                        const double *loads) {
    int ok;
    void *r = NULL;
    PyGILState_STATE g = py.GILState_Ensure();
    void *tuple = values_tuple(in, cage_angle, out, life, loads, inst->k.capacity);
    if (tuple != NULL) {
        r = call_python(inst->k_store, tuple);
        py.DecRef(tuple);
    }
    ok = r != NULL && r != py.None;
    if (r != NULL) py.DecRef(r);
    if (py.Err_Occurred() != NULL) py.Err_Clear();
    py.GILState_Release(g);
    return ok;
}

/* Push the kernel's state into the slave (kernel_store) if it stepped since the last push. */
static fmi2Status kernel_push(Instance *inst) {
    Kernel *k = &inst->k;
    if (!inst->k_dirty) return fmi2OK;
    int ok = store_values(inst, inst->in_val, k->cage_angle, k->out, k->life, k->loads);
    inst->k_dirty = 0;
    if (!ok) {   /* only a failure of the Python machinery itself: the slave is behind, stop here */
        inst->fast_on = inst->in_valid = inst->out_valid = inst->k_valid = 0;
        host_log(inst->host_functions, inst->host_env, inst->name, fmi2Error, "logStatusError",
                 "the loader could not pass the C step's state to the slave (Python error); the loader's fast "
                 "path is off for this instance");
        return fmi2Error;
    }
    inst->in_dirty = 0;    /* the slave holds the inputs */
    return fmi2OK;
}

/* One step in C (see "C step"); 1: done (state updated, dirty), 0: the Python step must decide. */
static int kernel_step(Instance *inst, double step_size) {
    Kernel *k = &inst->k;
    const double e_x = inst->in_val[0], e_y = inst->in_val[1], v_x = inst->in_val[2], v_y = inst->in_val[3];
    const double w_i = inst->in_val[4], w_o = inst->in_val[5];
    /* BallBearing.check_inputs: decided here only when clearly fine */
    if (!isfinite(e_x + e_y + v_x + v_y + w_i + w_o)) return 0;
    if (!(sqrt(e_x * e_x + e_y * e_y) < k->limit * (1.0 - 1e-9))) return 0;
    if (!(step_size >= 0.0)) return 0;
    /* BallBearing.advance_cage */
    const double cage_angle = k->cage_angle + step_size * (w_i * k->w_inner + w_o * k->w_outer);
    /* BallBearing.evaluate (damping_model 0 or 1: C is the constant damping or 0.0) */
    const double c = cos(cage_angle), s = sin(cage_angle);
    const double ex = c * e_x + s * e_y, ey = c * e_y - s * e_x;
    const double vx = c * v_x + s * v_y, vy = c * v_y - s * v_x;
    const double K = k->K, half = k->half, K15 = 1.5 * K, C = k->C;
    double fx = 0.0, fy = 0.0, kxx = 0.0, kxy = 0.0, kyy = 0.0, cc = 0.0, cs_ = 0.0, ss = 0.0, f_max = 0.0;
    int n_loaded = 0, r;
    double *loads = k->scratch;
    for (r = 0; r < k->n_balls; r++) {
        const double *b = k->balls + 5 * r;
        const double cr = b[0], sr = b[1], crr = b[2], crs = b[3], srr = b[4];
        const double delta = ex * cr + ey * sr - half;
        if (delta <= 0.0) {
            loads[r] = 0.0;
            continue;
        }
        const double root = sqrt(delta);
        const double w = K * delta * root;
        const double vr = vx * cr + vy * sr;
        const double kt = K15 * root;
        const double f = w + C * vr;
        if (f <= 0.0) {
            loads[r] = 0.0;
            continue;
        }
        loads[r] = f;
        fx += f * cr;
        fy += f * sr;
        kxx += kt * crr;
        kxy += kt * crs;
        kyy += kt * srr;
        cc += C * crr;
        cs_ += C * crs;
        ss += C * srr;
        n_loaded += 1;
        if (f > f_max) f_max = f;
    }
    const double c2 = c * c, s2 = s * s, cs2 = c * s;
    double out[K_OUTPUTS];
    out[0] = c * fx - s * fy;
    out[1] = s * fx + c * fy;
    out[2] = c2 * kxx - 2.0 * cs2 * kxy + s2 * kyy;
    out[3] = cs2 * (kxx - kyy) + (c2 - s2) * kxy;
    out[4] = s2 * kxx + 2.0 * cs2 * kxy + c2 * kyy;
    out[5] = c2 * cc - 2.0 * cs2 * cs_ + s2 * ss;
    out[6] = cs2 * (cc - ss) + (c2 - s2) * cs_;
    out[7] = s2 * cc + 2.0 * cs2 * cs_ + c2 * ss;
    out[8] = (double)n_loaded;
    out[9] = f_max;
    /* BearingStepping._evaluate's check */
    if (!isfinite(out[0] + out[1] + out[2] + out[3] + out[4] + out[5] + out[6] + out[7] + out[9] + cage_angle))
        return 0;
    /* LifeAccumulator.add(loads, w_i, w_o, step_size) with the end-of-step loads */
    double life[K_LIFE];
    memcpy(life, k->life, sizeof life);
    if (k->life_on) {
        const int z = k->n_balls;
        const double p_e = k->p_e;
        double s3 = 0.0, s103 = 0.0;
        for (r = 0; r < z; r++) {
            const double q = loads[r];
            if (q > 0.0) {
                s3 += q * q * q;
                const double qp = pow(q, p_e);
                if (!isfinite(qp)) return 0;   /* float ** raises OverflowError there: Python decides */
                s103 += qp;
            }
        }
        const double dn = fabs(w_i - w_o) * step_size / k->two_pi;
        if (s3 > 0.0) {
            const double q_rot3 = s3 / z;
            const double base = s103 / z;
            const double q_stat3 = pow(base, k->cube_of_stationary);
            if (!isfinite(q_stat3) && isfinite(base)) return 0;   /* OverflowError in Python */
            if (fabs(w_i - k->load_angular_velocity) >= fabs(w_o - k->load_angular_velocity)) {
                life[0] += q_rot3 * dn;
                life[1] += q_stat3 * dn;
            } else {
                life[0] += q_stat3 * dn;
                life[1] += q_rot3 * dn;
            }
        }
        life[2] += dn;
        life[3] += step_size;
    }
    /* accepted: the slave's _evaluate and add assign */
    k->cage_angle = cage_angle;
    memcpy(k->out, out, sizeof out);
    memcpy(k->life, life, sizeof life);
    memcpy(k->loads, loads, (size_t)k->n_balls * sizeof(double));
    for (r = k->n_balls; r < k->capacity; r++) k->loads[r] = 0.0;   /* _scratch beyond n_balls: never written */
    inst->k_dirty = 1;
    inst->k_steps++;
    return 1;
}

/* fmi2GetReal of an output the kernel computes (not loaded_balls: an Integer); 1 if vr is one */
static int kernel_real(const Instance *inst, fmi2ValueReference vr, fmi2Real *v) {
    const Kernel *k = &inst->k;
    for (int i = 0; i < K_OUTPUTS; i++)
        if (i != 8 && k->out_vr[i] == vr) {
            *v = k->out[i];
            return 1;
        }
    if (vr == k->cage_vr) {
        *v = k->cage_angle;
        return 1;
    }
    if (vr >= k->load_vr0 && vr - k->load_vr0 < (fmi2ValueReference)k->capacity) {
        *v = k->loads[vr - k->load_vr0];
        return 1;
    }
    return 0;
}

/* Pass the inputs set here and not yet to the slave on to it, in one fmi2SetReal. */
static fmi2Status flush_inputs(Instance *inst) {
    fmi2ValueReference vr[FAST_MAX_IN];
    fmi2Real v[FAST_MAX_IN];
    size_t n = 0;
    if (inst->in_dirty == 0) return fmi2OK;
    for (int i = 0; i < inst->n_in; i++)
        if (inst->in_dirty & (1u << i)) {
            vr[n] = inst->in_vr[i];
            v[n++] = inst->in_val[i];
        }
    inst->in_dirty = 0;
    return fmi.SetReal(inst->inner, vr, n, v);
}

/* Before a call is forwarded to pythonfmu: the slave gets the stored inputs; a call that may change
   inputs or outputs (``mutates``) drops the copies. */
static fmi2Status before_forward(Instance *inst, int mutates) {
    fmi2Status status = kernel_push(inst);    /* the C step's state first (inputs included) */
    if (status <= fmi2Warning) status = flush_inputs(inst);
    if (mutates) {
        inst->in_valid = inst->out_valid = inst->k_valid = 0;
        inst->k_retry = inst->k_load != NULL;   /* the kernel reloads before its next step */
    }
    return status;
}

/* Whether a forwarded fmi2<name> may change the slave's inputs or outputs (reads do not). */
/* After a call forwarded to pythonfmu: a slave that logged an error may hold a refusal to report at the next
   doStep (a refused get of a variable of another type, an unknown value reference): the kernel reloads, and
   its load hands that step to the Python step. */
static fmi2Status after_forward(Instance *inst, fmi2Status status) {
    if (inst->slave_error && inst->k_load != NULL) {
        inst->k_valid = 0;
        inst->k_retry = 1;
    }
    inst->slave_error = 0;
    return status;
}

static int mutating_call(const char *name) {
    return !(strncmp(name, "Get", 3) == 0 || strncmp(name, "Serialize", 9) == 0 ||
             strcmp(name, "FreeFMUstate") == 0 || strcmp(name, "DeSerializeFMUstate") == 0);
}

static int input_index(const Instance *inst, fmi2ValueReference vr) {
    for (int i = 0; i < inst->n_in; i++)
        if (inst->in_vr[i] == vr) return i;
    return -1;
}

#define FORWARD(ret, name, params, args)                                                          \
    EXPORT ret fmi2##name params {                                                                \
        if (c == NULL) return fmi2Error;                                                          \
        attach_thread();                                                                          \
        Instance *inst_ = (Instance *)c;                                                          \
        inst_->direct_error = 0;                                                                  \
        if (inst_->in_dirty || inst_->in_valid || inst_->out_valid || inst_->k_load != NULL) {    \
            fmi2Status flushed_ = before_forward(inst_, mutating_call(#name));                    \
            if (flushed_ > fmi2Warning) return flushed_;                                          \
        }                                                                                         \
        c = inst_->inner;                                                                         \
        inst_->slave_error = 0;                                                                   \
        return after_forward(inst_, fmi.name args);                                               \
    }
FMI2_FUNCTIONS(FORWARD)
#undef FORWARD

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    if (inst->fast_on && (n == 0 || (vr != NULL && v != NULL))) {
        size_t i;
        for (i = 0; i < n && input_index(inst, vr[i]) >= 0; i++) {}
        if (i == n) {   /* inputs only: kept here until the next doStep (or any forwarded call) */
            for (i = 0; i < n; i++) {
                int k = input_index(inst, vr[i]);
                inst->in_val[k] = v[i];
                inst->in_dirty |= 1u << k;
            }
            return fmi2OK;
        }
    }
    if (inst->in_dirty || inst->in_valid || inst->out_valid || inst->k_load != NULL) {
        fmi2Status flushed = before_forward(inst, 1);
        if (flushed > fmi2Warning) return flushed;
    }
    return fmi.SetReal(inst->inner, vr, n, v);
}

/* fmi2GetReal's body: also called by fmi2GetDirectionalDerivative, directly (a call of the exported
 * fmi2GetReal could bind through the PLT to another library's global fmi2GetReal, e.g. of an FMU or host
 * loaded RTLD_GLOBAL before us, which would then get our Instance*; the build links with -Bsymbolic too). */
static fmi2Status get_real(Instance *inst, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    inst->direct_error = 0;
    if (inst->fast_on && (n == 0 || (vr != NULL && v != NULL))) {
        size_t i;
        for (i = 0; i < n; i++) {
            int k = input_index(inst, vr[i]);
            if (k >= 0 && (inst->in_valid || (inst->in_dirty & (1u << k)))) {
                v[i] = inst->in_val[k];
                continue;
            }
            if (k >= 0) break;
            if (inst->k_valid && kernel_real(inst, vr[i], &v[i])) continue;
            if (!inst->out_valid) break;
            for (k = 0; k < inst->n_out && inst->out_vr[k] != vr[i]; k++) {}
            if (k == inst->n_out) break;
            v[i] = inst->out_val[k];
        }
        if (i == n) return fmi2OK;
    }
    if (inst->in_dirty || inst->k_dirty) {
        fmi2Status flushed = before_forward(inst, 0);
        if (flushed > fmi2Warning) return flushed;
    }
    inst->slave_error = 0;
    return after_forward(inst, fmi.GetReal(inst->inner, vr, n, v));
}

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    return get_real(inst, vr, n, v);
}

EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    if (inst->fast_on && inst->k_valid && n > 0 && vr != NULL && v != NULL) {   /* loaded_balls */
        size_t i;
        for (i = 0; i < n && vr[i] == inst->k.out_vr[8]; i++) {}
        if (i == n) {
            for (i = 0; i < n; i++) v[i] = (fmi2Integer)inst->k.out[8];
            return fmi2OK;
        }
    }
    if (inst->in_dirty || inst->in_valid || inst->out_valid || inst->k_load != NULL) {
        fmi2Status flushed = before_forward(inst, 0);
        if (flushed > fmi2Warning) return flushed;
    }
    inst->slave_error = 0;
    return after_forward(inst, fmi.GetInteger(inst->inner, vr, n, v));
}

/* One call of the slave's step with the current inputs (in_val complete: in_valid). */
static fmi2Status fast_step(Instance *inst, fmi2Real t, fmi2Real h) {
    void *args[2 + FAST_MAX_IN], *result = NULL, *tuple = NULL;
    int n = 2 + inst->n_in, i, made = 0;
    fmi2Status status;
    PyGILState_STATE g = py.GILState_Ensure();
    args[0] = py.Float_FromDouble(t);
    args[1] = py.Float_FromDouble(h);
    for (i = 0; i < inst->n_in; i++) args[2 + i] = py.Float_FromDouble(inst->in_val[i]);
    for (i = 0; i < n; i++) made += args[i] != NULL;
    if (made == n) {
        if (py.Object_Vectorcall != NULL) {
            result = py.Object_Vectorcall(inst->step, args, (size_t)n, NULL);
        } else if ((tuple = py.Tuple_New(n)) != NULL) {
            for (i = 0; i < n; i++) {
                py.IncRef(args[i]);   /* PyTuple_SetItem steals one reference */
                py.Tuple_SetItem(tuple, i, args[i]);
            }
            result = py.Object_Call(inst->step, tuple, NULL);
            py.DecRef(tuple);
        }
    }
    for (i = 0; i < n; i++)
        if (args[i] != NULL) py.DecRef(args[i]);
    if (result == NULL) {
        /* only a failure of the Python machinery itself (the slave's step catches everything) */
        py.Err_Clear();
        status = fmi2Error;
    } else if (result == py.None) {
        inst->in_dirty = 0;          /* the slave holds the inputs */
        inst->out_valid = 0;         /* refused: outputs unchanged, but keep no copy that could be wrong */
        status = fmi2Discard;
    } else {
        inst->in_dirty = 0;
        status = fmi2OK;
        inst->out_valid = 1;
        ptrdiff_t size = py.Tuple_Size(result);
        for (i = 0; i < inst->n_out; i++) {
            if (inst->out_index[i] >= size) {
                inst->out_valid = 0;
                break;
            }
            inst->out_val[i] = py.Float_AsDouble(py.Tuple_GetItem(result, inst->out_index[i]));
        }
        if (py.Err_Occurred() != NULL) {
            py.Err_Clear();
            inst->out_valid = 0;     /* not a tuple of floats: outputs are read through pythonfmu */
        }
        py.DecRef(result);
    }
    int queued = inst->queue == NULL ? status == fmi2Discard : py.List_Size(inst->queue) != 0;
    py.GILState_Release(g);
    if (result == NULL) {
        inst->fast_on = inst->in_valid = inst->out_valid = 0;
        host_log(inst->host_functions, inst->host_env, inst->name, fmi2Error, "logStatusError",
                 "fmi2DoStep: the slave's step could not be called (Python error); the loader's fast path is "
                 "off for this instance");
    } else if (queued) {
        /* pythonfmu sends the messages the slave queued during a call at its end: an empty fmi2GetReal
           empties the queue exactly as pythonfmu's fmi2DoStep would have */
        fmi2Real none[1];
        fmi.GetReal(inst->inner, inst->in_vr, 0, none);
    }
    return status;
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    if (inst->fast_on && !inst->in_valid) {   /* the slave's current inputs, once */
        fmi2Status status = flush_inputs(inst);
        if (status <= fmi2Warning) status = fmi.GetReal(inst->inner, inst->in_vr, (size_t)inst->n_in, inst->in_val);
        inst->in_valid = status <= fmi2Warning;
    }
    if (inst->fast_on && inst->in_valid) {
        if (inst->k_load != NULL) {
            if (!inst->k_valid && inst->k_retry) {
                inst->k_retry = 0;
                inst->k_valid = kernel_load(inst);
            }
            if (inst->k_valid) {
                if (kernel_step(inst, h)) {
                    inst->out_valid = 0;
                    return fmi2OK;
                }
                /* the Python step decides (see "C step"), on the slave as the kernel left it */
                fmi2Status pushed = kernel_push(inst);
                if (pushed > fmi2Warning) return pushed;
                inst->k_valid = 0;
                inst->k_retry = 1;
            }
        }
        fmi2Status status = fast_step(inst, t, h);
        if (status != fmi2OK && inst->k_load != NULL) inst->k_retry = 1;   /* a pending error was consumed */
        return status;
    }
    if (inst->in_dirty || inst->in_valid || inst->out_valid || inst->k_load != NULL) {
        fmi2Status flushed = before_forward(inst, 1);
        if (flushed > fmi2Warning) return flushed;
    }
    return fmi.DoStep(inst->inner, t, h, noSetPrior);
}

/* ---- FMU states in C ----------------------------------------------------------------------------------
 * While the C step owns an instance's state, fmi2GetFMUstate copies it here (inputs, cage angle, outputs, life
 * sums, ball loads: everything of a saved state that can change after initialisation; parameters and load
 * ratings are fixed) into a CState, without a Python call; fmi2SetFMUstate of such a state on the instance
 * that saved it copies it back (the kernel's state, pushed to the slave before the next forwarded call) or,
 * when the C step does not own the state then, hands it to the slave with one kernel_store -- what the
 * slave's own-state restore (_set_fmu_state of a state it saved since its initialisation) assigns. A CState
 * is "materialised" into pythonfmu's state (kept in ``inner``) whenever pythonfmu must see it: serialisation,
 * a set on another instance, a restore of life sums that are not finite and >= 0 (the slave refuses it, as
 * without the C step), and before its instance is reset or freed: the owner's slave builds the state pythonfmu
 * would have saved from the CState's values without changing itself (materialise). States pythonfmu made
 * (fmi2GetFMUstate while the C step does not own the state, fmi2DeSerializeFMUstate) are pythonfmu's
 * pointers, forwarded as before; the loader tells its CStates apart by its list (no dereference of a
 * pointer it did not make), so foreign or doctored states are checked and refused by the slave as before. */
typedef struct CState {
    struct CState *next;
    Instance *owner;                    /* the instance that saved it (NULL: freed; then ``inner`` is set) */
    fmi2FMUstate inner;                 /* pythonfmu's state of the same content, or NULL (not materialised) */
    int has_c;                          /* the values below are the state (not yet materialised) */
    int busy;                           /* being materialised by a thread (its values in use, outside LOCK) */
    int capacity;                       /* length of loads */
    double in_val[6], cage_angle, out[K_OUTPUTS], life[K_LIFE];
    double *loads;
} CState;
static CState *cstates;                 /* every live CState; its fields are read and changed under LOCK */

/* Under LOCK: the CState at p, or NULL (no dereference of a pointer the loader did not make) */
static CState *find_locked(const void *p) {
    CState *s;
    for (s = cstates; s != NULL && (const void *)s != p; s = s->next) {}
    return s;
}

static CState *find_cstate(const void *p) {
    LOCK();
    CState *s = find_locked(p);
    UNLOCK();
    return s;
}

/* 1 if the life sums can be restored (finite, >= 0: what LifeAccumulator.restore accepts) */
static int life_ok(const double *life) {
    for (int i = 0; i < K_LIFE; i++)
        if (!(life[i] >= 0.0) || !isfinite(life[i])) return 0;
    return 1;
}

#define STATE_BUSY 99   /* materialise: another thread is materialising the state now */

/* Make pythonfmu's state of a CState: the owner's slave builds it from the saved values
 * (kernel_store(values, True) = _kernel_saved_state: pythonfmu 0.7's fmi2FMUstate is the PyObject its
 * _get_fmu_state returns) WITHOUT changing the owner's slave, so a thread using the owner meanwhile sees
 * nothing of it. The GIL is taken before LOCK (the order of the Python side's calls into the loader) and no
 * Python runs under LOCK; ``busy`` keeps the state's values for this thread while the slave builds it; the
 * callable is held by its own reference (the owner may be freed meanwhile: drop_step clears it under LOCK).
 * fmi2OK, STATE_BUSY, or fmi2Error (owner freed before, or a Python failure). */
static int materialise(CState *s) {
    int status = fmi2OK;
    void *store = NULL, *made = NULL;
    PyGILState_STATE g = py.GILState_Ensure();
    LOCK();
    if (find_locked(s) != s) {   /* freed meanwhile (by another thread) */
        status = fmi2Error;
    } else if (s->busy) {
        status = STATE_BUSY;
    } else if (s->has_c && s->inner == NULL) {
        if (s->owner != NULL && s->owner->k_store != NULL) {
            store = s->owner->k_store;
            py.IncRef(store);
            s->busy = 1;
        } else {
            status = fmi2Error;
        }
    }
    UNLOCK();
    if (store != NULL) {
        void *values = values_tuple(s->in_val, s->cage_angle, s->out, s->life, s->loads, s->capacity);
        void *flag = values != NULL ? py.Float_FromDouble(1.0) : NULL;
        void *args = flag != NULL ? py.Tuple_New(2) : NULL;
        if (args != NULL) {
            py.Tuple_SetItem(args, 0, values);   /* steals */
            py.Tuple_SetItem(args, 1, flag);
            values = flag = NULL;
            made = py.Object_Call(store, args, NULL);
            py.DecRef(args);
        }
        if (values != NULL) py.DecRef(values);
        if (flag != NULL) py.DecRef(flag);
        if (made == py.None) {
            py.DecRef(made);
            made = NULL;
        }
        if (py.Err_Occurred() != NULL) py.Err_Clear();
        py.DecRef(store);
        double *loads = NULL;
        LOCK();
        s->busy = 0;
        if (made != NULL) {
            s->inner = (fmi2FMUstate)made;
            s->has_c = 0;
            loads = s->loads;
            s->loads = NULL;
        }
        UNLOCK();
        free(loads);
        if (made == NULL) status = fmi2Error;
    }
    py.GILState_Release(g);
    return status;
}

/* Before an instance is reset or freed: its CStates become pythonfmu's states (the slave is still there). */
static void materialise_all(Instance *inst) {
    CState *s, *mine[64];
    int n, i, more = 1;
    while (more) {
        n = 0;
        more = 0;
        LOCK();
        for (s = cstates; s != NULL; s = s->next)
            if (s->owner == inst && s->has_c && !s->busy) {   /* busy: another thread is making it */
                if (n == 64) more = 1;
                else mine[n++] = s;
            }
        UNLOCK();
        for (i = 0; i < n; i++)
            if (materialise(mine[i]) == fmi2Error) {
                LOCK();
                if (!mine[i]->busy) mine[i]->has_c = 0;   /* cannot be made: any later use is refused (fmi2Error) */
                UNLOCK();
            }
    }
}

static void disown_all(Instance *inst) {
    LOCK();
    for (CState *s = cstates; s != NULL; s = s->next)
        if (s->owner == inst) s->owner = NULL;
    UNLOCK();
}

/* pythonfmu's state of CState s (materialised first), with a reference of the caller's own (GIL taken here,
   released by release_inner), so a concurrent update or free of s cannot free it under the caller; NULL if
   it cannot be made (``*status`` says why). */
static void *acquire_inner(CState *s, fmi2Status *status, PyGILState_STATE *g) {
    int made = materialise(s);
    void *inner = NULL;
    *g = py.GILState_Ensure();
    if (made == fmi2OK) {
        LOCK();
        if (find_locked(s) == s && s->inner != NULL) {
            inner = s->inner;
            py.IncRef(inner);
        }
        UNLOCK();
    }
    *status = inner != NULL ? fmi2OK : fmi2Error;
    if (inner == NULL) py.GILState_Release(*g);
    return inner;
}

static void release_inner(void *inner, PyGILState_STATE g) {
    py.DecRef(inner);
    py.GILState_Release(g);
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Instance *inst = (Instance *)c;
    if (inst == NULL || state == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    CState *s = *state != NULL ? find_cstate(*state) : NULL;
    fmi2FMUstate old = NULL;
    if (inst->fast_on && inst->k_valid && (*state == NULL || s != NULL)) {   /* the C step owns the state */
        int capacity = inst->k.capacity;
        if (s == NULL) {
            s = (CState *)calloc(1, sizeof *s);
            double *loads = (double *)malloc((size_t)capacity * sizeof(double));
            if (s == NULL || loads == NULL) {
                free(s);
                free(loads);
                return fmi2Error;
            }
            s->loads = loads;
            s->capacity = capacity;
            LOCK();
        } else {   /* FMI: *state is a state saved earlier: update it */
            LOCK();
            if (find_locked(s) != s || s->busy) {   /* freed meanwhile, or being made by another thread */
                UNLOCK();
                return fmi2Error;
            }
            if (s->loads == NULL || s->capacity != capacity) {
                double *loads = (double *)realloc(s->loads, (size_t)capacity * sizeof(double));
                if (loads == NULL) {
                    UNLOCK();
                    return fmi2Error;
                }
                s->loads = loads;
                s->capacity = capacity;
            }
            old = s->inner;
            s->inner = NULL;
        }
        s->owner = inst;
        s->has_c = 1;
        memcpy(s->in_val, inst->in_val, sizeof s->in_val);
        s->cage_angle = inst->k.cage_angle;
        memcpy(s->out, inst->k.out, sizeof s->out);
        memcpy(s->life, inst->k.life, sizeof s->life);
        memcpy(s->loads, inst->k.loads, (size_t)capacity * sizeof(double));
        if (*state == NULL) {
            s->next = cstates;
            cstates = s;
        }
        UNLOCK();
        if (old != NULL) fmi.FreeFMUstate(inst->inner, &old);
        inst->k_states++;
        *state = s;
        return fmi2OK;
    }
    fmi2Status status = before_forward(inst, 0);
    if (status > fmi2Warning) return status;
    if (s == NULL) return fmi.GetFMUstate(inst->inner, state);
    /* one of ours, saved while the C step owned the state: now pythonfmu's, in the same CState */
    fmi2FMUstate made = NULL;
    status = fmi.GetFMUstate(inst->inner, &made);
    if (status > fmi2Warning) return status;
    double *loads = NULL;
    LOCK();
    if (find_locked(s) != s || s->busy) {
        UNLOCK();
        fmi.FreeFMUstate(inst->inner, &made);
        return fmi2Error;
    }
    old = s->inner;
    loads = s->loads;
    s->loads = NULL;
    s->inner = made;
    s->has_c = 0;
    s->owner = inst;
    UNLOCK();
    free(loads);
    if (old != NULL) fmi.FreeFMUstate(inst->inner, &old);
    return status;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    CState *s = state != NULL ? find_cstate(state) : NULL;
    if (s != NULL) {
        /* this instance's own state, with usable life sums (else the slave checks it and refuses, see below) */
        int own = 0;
        LOCK();
        if (find_locked(s) == s && !s->busy && s->has_c && s->owner == inst && s->capacity == inst->k.capacity &&
            (!inst->k.life_on || life_ok(s->life))) {
            own = 1;
            if (inst->fast_on && inst->k_valid) {   /* back into the kernel; the slave gets it at the next push */
                memcpy(inst->in_val, s->in_val, sizeof s->in_val);
                inst->k.cage_angle = s->cage_angle;
                memcpy(inst->k.out, s->out, sizeof s->out);
                memcpy(inst->k.life, s->life, sizeof s->life);
                memcpy(inst->k.loads, s->loads, (size_t)s->capacity * sizeof(double));
                UNLOCK();
                inst->in_valid = 1;
                inst->in_dirty = 0;
                inst->out_valid = 0;
                inst->k_dirty = 1;
                return fmi2OK;
            }
        }
        UNLOCK();
        if (own) {   /* the slave has the state now: one kernel_store (values copied: s may change meanwhile) */
            CState copy;
            memset(&copy, 0, sizeof copy);
            double *loads = (double *)malloc((size_t)inst->k.capacity * sizeof(double));
            if (loads == NULL) return fmi2Error;
            LOCK();
            own = find_locked(s) == s && !s->busy && s->has_c && s->owner == inst && s->capacity == inst->k.capacity;
            if (own) {
                copy = *s;
                memcpy(loads, s->loads, (size_t)s->capacity * sizeof(double));
            }
            UNLOCK();
            fmi2Status status = own ? before_forward(inst, 1) : fmi2Error;
            if (status <= fmi2Warning &&
                !store_values(inst, copy.in_val, copy.cage_angle, copy.out, copy.life, loads))
                status = fmi2Error;
            free(loads);
            if (status <= fmi2Warning) inst->in_dirty = 0;
            return status;
        }
        /* another instance's (or unusable sums): pythonfmu's state, which the slave checks */
        fmi2Status status;
        PyGILState_STATE g;
        void *inner = acquire_inner(s, &status, &g);
        if (inner == NULL) return status;
        status = before_forward(inst, 1);
        if (status <= fmi2Warning) status = fmi.SetFMUstate(inst->inner, inner);
        release_inner(inner, g);
        return status;
    }
    fmi2Status flushed = before_forward(inst, 1);
    if (flushed > fmi2Warning) return flushed;
    return fmi.SetFMUstate(inst->inner, state);
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Instance *inst = (Instance *)c;
    if (inst == NULL || state == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    if (*state == NULL) return fmi.FreeFMUstate(inst->inner, state);
    LOCK();
    CState *s = find_locked(*state);
    if (s != NULL && s->busy) {   /* another thread is making it now: not freed (FMI: a state is not shared) */
        UNLOCK();
        return fmi2Error;
    }
    if (s != NULL)
        for (CState **p = &cstates; *p != NULL; p = &(*p)->next)
            if (*p == s) {
                *p = s->next;
                break;
            }
    UNLOCK();
    if (s == NULL) return fmi.FreeFMUstate(inst->inner, state);
    fmi2Status status = fmi2OK;
    if (s->inner != NULL) status = fmi.FreeFMUstate(inst->inner, &s->inner);
    free(s->loads);
    free(s);
    *state = NULL;
    return status;
}

/* fmi2SerializedFMUstateSize (``only_size``: the size into ``*size_out``) or fmi2SerializeFMUstate: a state saved
   in C is serialized as pythonfmu's state made from it (the same bytes as without the C step). */
static fmi2Status serialize(fmi2Component c, fmi2FMUstate state, int only_size, fmi2Byte bytes[], size_t size,
                            size_t *size_out) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    fmi2Status status = before_forward(inst, 0);
    if (status > fmi2Warning) return status;
    CState *s = state != NULL ? find_cstate(state) : NULL;
    PyGILState_STATE g;
    void *inner = state;
    if (s != NULL && (inner = acquire_inner(s, &status, &g)) == NULL) return status;
    status = only_size ? fmi.SerializedFMUstateSize(inst->inner, inner, size_out)
                           : fmi.SerializeFMUstate(inst->inner, inner, bytes, size);
    if (s != NULL) release_inner(inner, g);
    return status;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    return serialize(c, state, 1, NULL, 0, size);
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    return serialize(c, state, 0, bytes, size, NULL);
}

/* For tests and benchmarks: the number of FMU states ``c`` saved in C. */
EXPORT long long bearingLoaderKernelStates(const void *c) { return live_counter(c, 2, -1); }

EXPORT fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    fmi2Status flushed = before_forward(inst, 1);
    inst->fast_on = 0;
    if (flushed > fmi2Warning) return flushed;
    return fmi.Terminate(inst->inner);
}

EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    materialise_all(inst);      /* states saved in C become pythonfmu's before the slave goes */
    drop_step(inst);            /* pythonfmu builds a new slave, which registers again */
    registering = inst;
    fmi2Status status = fmi.Reset(inst->inner);
    registering = NULL;
    return status;
}

/* The host's logging wish is the loader's filter; pythonfmu's own logging stays on (see pass_message). */
EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    fmi2Status status = fmi.SetDebugLogging(inst->inner, 1, 0, NULL);
    if (status <= fmi2Warning) set_categories(inst, loggingOn, n, categories);
    return status;
}

/* pythonfmu 0.7 returns fmi2Fatal for any exception in exit_initialization_mode. Our slaves (BallBearing,
   JournalClearance, SliderCrank) raise there only after validating, before assigning anything that a later
   call depends on (the instance keeps no half-built model: doStep refuses until a successful
   initialisation), and keep no state shared between instances; so the instance is intact and only this
   call failed: fmi2Error in FMI 2.0's terms (the host may free or reset it). Departure from pythonfmu
   documented in docs/fmu-interface.md ("Errors"). */
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
    inst->direct_error = 0;
    inst->in_exit_initialization = 1;
    fmi2Status flushed = before_forward(inst, 1);
    fmi2Status status = flushed > fmi2Warning ? flushed : fmi.ExitInitializationMode(inst->inner);
    inst->in_exit_initialization = 0;
    if (status <= fmi2Warning && inst->step != NULL) {   /* initialised: the fast path is on */
        inst->fast_on = 1;
        inst->in_valid = inst->out_valid = 0;
        inst->in_dirty = 0;
    }
    return status == fmi2Fatal ? fmi2Error : status;
}

/* d unknown / d known from the FMU's tangent outputs: DD_TABLE rows {unknown vr, known vr, source vr}. */
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                               const fmi2ValueReference vKnown[], size_t nKnown,
                                               const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    attach_thread();
#if DD_COUNT > 0
    static const unsigned table[DD_COUNT][3] = DD_TABLE;
    size_t i, j, k, n = nUnknown * nKnown;
    if (n == 0) {
        for (i = 0; i < nUnknown; i++) dvUnknown[i] = 0.0;
        return fmi2OK;
    }
    fmi2ValueReference *sources = (fmi2ValueReference *)malloc(n * sizeof *sources);
    fmi2Real *partials = (fmi2Real *)malloc(n * sizeof *partials);
    fmi2Status status = fmi2Error;
    if (sources == NULL || partials == NULL) goto done;
    for (i = 0; i < nUnknown; i++) {
        for (j = 0; j < nKnown; j++) {
            for (k = 0; k < DD_COUNT; k++)
                if (table[k][0] == vUnknown[i] && table[k][1] == vKnown[j]) break;
            if (k == DD_COUNT) {
                char message[512];
                snprintf(message, sizeof message,
                         "fmi2GetDirectionalDerivative: the partial derivative of the variable with valueReference "
                         "%u with respect to valueReference %u is not available (available: the force outputs "
                         "with respect to the eccentricity and its rate, from the tangent stiffness and damping "
                         "outputs; docs/fmu-interface.md)",
                         vUnknown[i], vKnown[j]);
                host_log(inst->host_functions, inst->host_env, inst->name, fmi2Error, "logStatusError", message);
                goto done;
            }
            sources[i * nKnown + j] = table[k][2];
        }
    }
    status = get_real(inst, sources, n, partials);  /* the tangent outputs, in one call (the C step's too) */
    if (status <= fmi2Warning) {
        for (i = 0; i < nUnknown; i++) {
            double sum = 0.0;
            for (j = 0; j < nKnown; j++) sum += partials[i * nKnown + j] * dvKnown[j];
            dvUnknown[i] = sum;
        }
    }
done:
    free(sources);
    free(partials);
    return status;
#else
    return fmi.GetDirectionalDerivative(inst->inner, vUnknown, nUnknown, vKnown, nKnown, dvKnown, dvUnknown);
#endif
}
