/*
 * A minimal native FMI 2.0 co-simulation host, for tests and benchmarks of the FMUs in a non-Python
 * process (tests/test_native_host.py, benchmarks/fmu_step.py):
 *
 *   host BINARY RESOURCE_URI GUID N_INSTANCES N_STEPS MODE IN_VRS OUT_VRS
 *
 * MODE "seq" steps the instances one after the other from the main thread, "threads" each from its own
 * thread at the same time. IN_VRS (6) and OUT_VRS (2) are comma-separated value references of
 * e_x, e_y, v_x, v_y, omega_inner, omega_outer and of F_x, F_y. Every step sets the 6 inputs, calls
 * fmi2DoStep(h = 1e-5 s) and gets the 2 outputs (the inputs cycle through 64 states of |e| = 30 um).
 * Prints per instance "instance K F_x F_y sum_F_x sum_F_y" (%.17g), then "cycle_us T" (mean time of one
 * set/step/get cycle of the first run) and exits 0 after freeing everything; exit 2 when
 * instantiation fails, 3 when a call fails. The logger prints "log [category] message" on stderr.
 */
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef int fmi2Status;
typedef void (*Logger)(void *, const char *, fmi2Status, const char *, const char *, ...);
typedef struct {
    Logger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, fmi2Status);
    void *componentEnvironment;
} Callbacks;

static fmi2Component (*Instantiate)(const char *, int, const char *, const char *, const Callbacks *, int, int);
static void (*FreeInstance)(fmi2Component);
static fmi2Status (*SetupExperiment)(fmi2Component, int, double, double, int, double);
static fmi2Status (*EnterInit)(fmi2Component), (*ExitInit)(fmi2Component), (*Terminate)(fmi2Component);
static fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference *, size_t, const double *);
static fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference *, size_t, double *);
static fmi2Status (*DoStep)(fmi2Component, double, double, int);

static void logger(void *env, const char *name, fmi2Status status, const char *category, const char *message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "log %s status %d [%s] ", name ? name : "(null)", status, category ? category : "(null)");
    va_start(ap, message);
    vfprintf(stderr, message ? message : "(null)", ap);
    va_end(ap);
    fputc('\n', stderr);
}

static fmi2ValueReference vr_in[6], vr_out[2];
static int n_steps;

typedef struct {
    fmi2Component c;
    double F[2], sum[2], seconds;
    int failed;
} Run;

static void *step_instance(void *arg) {
    Run *run = (Run *)arg;
    double x[6], y[2] = {0, 0}, h = 1e-5;
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (int i = 0; i < n_steps; i++) {
        double a = 2 * M_PI * (i % 64) / 64.0;
        x[0] = 3e-5 * cos(a); x[1] = 3e-5 * sin(a); x[2] = -0.01 * sin(a); x[3] = 0.01 * cos(a);
        x[4] = 100.0; x[5] = 0.0;
        if (SetReal(run->c, vr_in, 6, x) || DoStep(run->c, i * h, h, 1) || GetReal(run->c, vr_out, 2, y)) {
            run->failed = 1;
            break;
        }
        run->sum[0] += y[0];
        run->sum[1] += y[1];
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    run->seconds = (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
    run->F[0] = y[0];
    run->F[1] = y[1];
    return NULL;
}

static void parse_vrs(const char *text, fmi2ValueReference *out, int n) {
    char *end;
    for (int i = 0; i < n; i++) {
        out[i] = (fmi2ValueReference)strtoul(text, &end, 10);
        text = *end ? end + 1 : end;
    }
}

#define SYM(var, name)                                                           \
    if ((*(void **)&var = dlsym(lib, name)) == NULL) {                            \
        fprintf(stderr, "missing %s\n", name);                                    \
        return 1;                                                                 \
    }

int main(int argc, char **argv) {
    if (argc < 9) {
        fprintf(stderr, "usage: %s BINARY RESOURCE_URI GUID N_INSTANCES N_STEPS seq|threads IN_VRS OUT_VRS\n", argv[0]);
        return 1;
    }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 1;
    }
    SYM(Instantiate, "fmi2Instantiate") SYM(FreeInstance, "fmi2FreeInstance")
    SYM(SetupExperiment, "fmi2SetupExperiment") SYM(EnterInit, "fmi2EnterInitializationMode")
    SYM(ExitInit, "fmi2ExitInitializationMode") SYM(Terminate, "fmi2Terminate")
    SYM(SetReal, "fmi2SetReal") SYM(GetReal, "fmi2GetReal") SYM(DoStep, "fmi2DoStep")
    int n = atoi(argv[4]), threads = strcmp(argv[6], "threads") == 0;
    n_steps = atoi(argv[5]);
    parse_vrs(argv[7], vr_in, 6);
    parse_vrs(argv[8], vr_out, 2);
    Callbacks cb = {logger, calloc, free, NULL, NULL};
    Run *runs = (Run *)calloc((size_t)n, sizeof(Run));
    pthread_t *tids = (pthread_t *)calloc((size_t)n, sizeof(pthread_t));
    for (int k = 0; k < n; k++) {
        char name[32];
        snprintf(name, sizeof name, "bearing%d", k);
        runs[k].c = Instantiate(name, 1, argv[3], argv[2], &cb, 0, 0);
        if (runs[k].c == NULL) {
            fprintf(stderr, "instantiate failed\n");
            return 2;
        }
        if (SetupExperiment(runs[k].c, 0, 0.0, 0.0, 0, 0.0) || EnterInit(runs[k].c) || ExitInit(runs[k].c)) {
            fprintf(stderr, "initialisation failed\n");
            return 3;
        }
    }
    for (int k = 0; k < n; k++) {
        if (threads)
            pthread_create(&tids[k], NULL, step_instance, &runs[k]);
        else
            step_instance(&runs[k]);
    }
    int failed = 0;
    for (int k = 0; k < n; k++) {
        if (threads) pthread_join(tids[k], NULL);
        failed |= runs[k].failed;
        printf("instance %d %.17g %.17g %.17g %.17g\n", k, runs[k].F[0], runs[k].F[1], runs[k].sum[0], runs[k].sum[1]);
    }
    printf("cycle_us %.4f\n", n_steps ? runs[0].seconds / n_steps * 1e6 : 0.0);
    for (int k = 0; k < n; k++) {
        Terminate(runs[k].c);
        FreeInstance(runs[k].c);
    }
    free(runs);
    free(tids);
    fflush(stdout);
    return failed ? 3 : 0;
}
