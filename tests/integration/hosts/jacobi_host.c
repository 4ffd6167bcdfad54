/* A minimal FMI 2.0 co-simulation host in C, with no Python of its own: it loads the FMUs named in a
   plan file, steps them as a Jacobi system (every FMU gets the outputs of the step before, as the
   fmpy and libcosim masters do) and prints the recorded output of the last steps.

   Plan file, one directive a line:
     fmu DIR MODEL_IDENTIFIER GUID          (an extracted FMU; index 0, 1, ... in order)
     uri FMU URI                            (its fmuResourceLocation, the rest of the line; default
                                             file://DIR/resources)
     connect SRC OUT_VR DST IN_VR           (a Real output to a Real input)
     record FMU VR                          (the Real output printed, one value a line)
     steps K / step DT / last N             (K steps of DT; print the last N recorded values)
     wrong_step FMU H                       (once, before stepping: a doStep of H s, status printed)
   Output: "python-loaded-before: 0|1", "wrong-step-status: S", then "value: X" lines. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define MAX_FMUS 8
#define MAX_LINKS 16

typedef struct {
    char dir[2048], id[256], guid[256], uri[4096];
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2DoStepTYPE *do_step;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
    fmi2TerminateTYPE *terminate;
} Fmu;

typedef struct { int src; fmi2ValueReference out; int dst; fmi2ValueReference in; double value; } Link;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list args;
    (void)env; (void)category;
    printf("log %s [%d]: ", name, (int)status);
    va_start(args, message);
    vprintf(message, args);
    va_end(args);
    printf("\n");
    fflush(stdout);
}

static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (f == NULL) { fprintf(stderr, "missing %s\n", name); exit(2); }
    return f;
}

static void load(Fmu *f, const fmi2CallbackFunctions *cb) {
    char path[4096], resources[4096];
    void *lib;
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", f->dir, f->id);
    if ((lib = dlopen(path, RTLD_NOW | RTLD_LOCAL)) == NULL) { fprintf(stderr, "dlopen: %s\n", dlerror()); exit(2); }
    f->instantiate = symbol(lib, "fmi2Instantiate");
    f->setup = symbol(lib, "fmi2SetupExperiment");
    f->enter = symbol(lib, "fmi2EnterInitializationMode");
    f->exit_init = symbol(lib, "fmi2ExitInitializationMode");
    f->do_step = symbol(lib, "fmi2DoStep");
    f->get_real = symbol(lib, "fmi2GetReal");
    f->set_real = symbol(lib, "fmi2SetReal");
    f->terminate = symbol(lib, "fmi2Terminate");
    if (f->uri[0] != '\0')
        snprintf(resources, sizeof resources, "%s", f->uri);
    else
        snprintf(resources, sizeof resources, "file://%s/resources", f->dir);
    f->c = f->instantiate(f->id, fmi2CoSimulation, f->guid, resources, cb, fmi2False, fmi2False);
    if (f->c == NULL) { fprintf(stderr, "fmi2Instantiate of %s failed\n", f->id); exit(3); }
    if (f->setup(f->c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning || f->enter(f->c) > fmi2Warning
        || f->exit_init(f->c) > fmi2Warning) { fprintf(stderr, "initialising %s failed\n", f->id); exit(3); }
}

static void check(fmi2Status s, const char *what, long k) {
    if (s > fmi2Warning) { fprintf(stderr, "%s failed at step %ld (status %d)\n", what, k, (int)s); exit(4); }
}

int main(int argc, char **argv) {
    static Fmu fmus[MAX_FMUS];
    static Link links[MAX_LINKS];
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    int n_fmus = 0, n_links = 0, rec_fmu = -1, wrong_fmu = -1, uri_fmu = -1;
    static char uri[4096];
    fmi2ValueReference rec_vr = 0;
    long steps = 0, last = 1, k;
    double dt = 0.0, wrong_h = 0.0, *recorded;
    char line[8192];
    FILE *plan;
    if (argc != 2 || (plan = fopen(argv[1], "r")) == NULL) { fprintf(stderr, "usage: jacobi_host PLAN\n"); return 2; }
    while (fgets(line, sizeof line, plan)) {
        Fmu *f = &fmus[n_fmus];
        Link *l = &links[n_links];
        if (sscanf(line, "fmu %2047s %255s %255s", f->dir, f->id, f->guid) == 3 && n_fmus < MAX_FMUS) n_fmus++;
        else if (sscanf(line, "connect %d %u %d %u", &l->src, &l->out, &l->dst, &l->in) == 4 && n_links < MAX_LINKS) n_links++;
        else if (sscanf(line, "record %d %u", &rec_fmu, &rec_vr) == 2) {}
        else if (sscanf(line, "steps %ld", &steps) == 1) {}
        else if (sscanf(line, "step %lf", &dt) == 1) {}
        else if (sscanf(line, "last %ld", &last) == 1) {}
        else if (sscanf(line, "wrong_step %d %lf", &wrong_fmu, &wrong_h) == 2) {}
        else if (sscanf(line, "uri %d %4095[^\n]", &uri_fmu, uri) == 2 && uri_fmu >= 0 && uri_fmu < MAX_FMUS)
            snprintf(fmus[uri_fmu].uri, sizeof fmus[uri_fmu].uri, "%s", uri);
    }
    fclose(plan);
    printf("python-loaded-before: %d\n", dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL);
    for (int i = 0; i < n_fmus; i++) load(&fmus[i], &cb);
    if (wrong_fmu >= 0) printf("wrong-step-status: %d\n", (int)fmus[wrong_fmu].do_step(fmus[wrong_fmu].c, 0.0, wrong_h, fmi2True));
    for (int j = 0; j < n_links; j++) check(fmus[links[j].src].get_real(fmus[links[j].src].c, &links[j].out, 1, &links[j].value), "get", -1);
    recorded = calloc((size_t)(steps > 0 ? steps : 1), sizeof *recorded);
    for (k = 0; k < steps; k++) {
        for (int j = 0; j < n_links; j++)  /* Jacobi: inputs are the outputs of the step before */
            check(fmus[links[j].dst].set_real(fmus[links[j].dst].c, &links[j].in, 1, &links[j].value), "set", k);
        for (int i = 0; i < n_fmus; i++) check(fmus[i].do_step(fmus[i].c, k * dt, dt, fmi2True), "doStep", k);
        for (int j = 0; j < n_links; j++)
            check(fmus[links[j].src].get_real(fmus[links[j].src].c, &links[j].out, 1, &links[j].value), "get", k);
        if (rec_fmu >= 0) check(fmus[rec_fmu].get_real(fmus[rec_fmu].c, &rec_vr, 1, &recorded[k]), "get", k);
    }
    for (k = steps - last; k < steps; k++) if (k >= 0) printf("value: %.17g\n", recorded[k]);
    for (int i = 0; i < n_fmus; i++) fmus[i].terminate(fmus[i].c);
    free(recorded);
    return 0;  /* a normal exit: the libraries' destructors run (docs/fmi-hosts.md, Linux item 4) */
}
