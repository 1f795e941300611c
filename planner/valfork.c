/* A fork server inside VAL's own `Validate` (LD_PRELOAD), as AFL runs the programs it tests.

   Starting `Validate` costs more than most short checks: the kernel's exec, loading and relocating libVAL.so
   (thousands of symbol lookups) and glibc's start-up. Preloaded with PLANHRC_VALFORK_FD set, this library takes
   over `__libc_start_main`, after every library (libVAL.so included) is loaded, relocated and initialised, and
   before VAL's `main`: the process then serves requests on that descriptor (a SOCK_SEQPACKET socket) and never
   runs `main` itself. For each request it forks a *run*, which calls glibc's real `__libc_start_main` with the
   request's arguments: VAL's unchanged `main` reads the files and checks the plan exactly as
   `Validate DOMAIN PROBLEM PLAN` does, its output on the descriptor the request passed.

   Request: one message, the niceness increment and then VAL's arguments, each ended by a NUL byte, with one
   descriptor (SCM_RIGHTS) for the run's standard output and error. Reply: the run's pid (an int), or -1 (a bad
   request, or MAX_RUNS going on). The run leads a process group of its own (kill the group to stop it). When it
   ends the server writes "\n" TRAILER " <status> <cpu>\n" after its output (the exit code, or minus the signal
   that ended it; the CPU the run used, user + system, in microseconds, as `wait4` gives it: from the fork on, so
   not the start-up the server did once) and closes its copy of the descriptor: the reader then sees end-of-file.
   The server writes one byte when it is ready and exits when the other end of its socket closes; a run dies with
   the server (parent-death signal), so no run outlives the service that asked for it.
   Without PLANHRC_VALFORK_FD the library does nothing: `Validate` runs as usual.

   Past the domain (PLANHRC_VALFORK_AFTER, the path of a problem that is not there, with PLANHRC_VALFORK_PLAN, a
   plan's): the process runs VAL's `main` itself, on `Validate DOMAIN AFTER PLAN`, as a run would, and serves
   requests only when VAL opens AFTER: VAL has then read and parsed the domain, and does nothing before that open
   that depends on the problem or the plan (it reads its files in order: the domain, the problem, the plan). A run
   is forked right there: it opens the request's problem in place of AFTER (and later the request's plan in place
   of PLAN) and goes on with VAL's `main` from that point, so it does what `Validate DOMAIN PROBLEM PLAN` does once
   the domain is parsed, without parsing it again. A request names the same three files, and its domain must be the
   server's (else it is refused). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <sys/wait.h>
#include <unistd.h>

#define TRAILER "planhrc-valfork-status"
#define MAX_REQUEST 65536
#define MAX_ARGS 64
#define MAX_RUNS 256

typedef int (*main_fn)(int, char **, char **);
typedef int (*start_fn)(main_fn, int, char **, void (*)(void), void (*)(void), void (*)(void), void *);

/* the runs going on: pid and the descriptor their status is written to (the server's copy of their output) */
static pid_t run_pid[MAX_RUNS];
static int run_out[MAX_RUNS];

static void write_all(int fd, const char *data, size_t len) {
    while (len > 0) {
        ssize_t n = write(fd, data, len);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return;
        data += n;
        len -= (size_t)n;
    }
}

/* The decimal digits of `value` at `out` (no sprintf: async-signal-safe); how many. */
static size_t put_digits(char *out, unsigned long long value) {
    char digits[24];
    size_t k = 0, len = 0;
    do {
        digits[k++] = (char)('0' + value % 10);
        value /= 10;
    } while (value > 0);
    while (k > 0) out[len++] = digits[--k];
    return len;
}

/* SIGCHLD: each run that ended gets its status and its CPU written after its output, and its descriptor closed
   (the reader then sees end-of-file). Only async-signal-safe calls (`wait4` is the system call `waitpid` makes). */
static void reap(int sig) {
    (void)sig;
    int saved = errno, status = 0;
    struct rusage usage;
    pid_t pid;
    while ((pid = wait4(-1, &status, WNOHANG, &usage)) > 0) {
        for (int i = 0; i < MAX_RUNS; i++) {
            if (run_pid[i] != pid) continue;
            int code = WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status);
            unsigned long long cpu_us =
                (unsigned long long)(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) * 1000000ULL +
                (unsigned long long)(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
            char line[96] = "\n" TRAILER " ";
            size_t len = strlen(line);
            if (!WIFEXITED(status)) line[len++] = '-'; /* as Python's returncode says a signal */
            len += put_digits(line + len, (unsigned long long)code);
            line[len++] = ' ';
            len += put_digits(line + len, cpu_us);
            line[len++] = '\n';
            write_all(run_out[i], line, len);
            close(run_out[i]);
            run_pid[i] = 0;
            run_out[i] = -1;
            break;
        }
    }
    errno = saved;
}

/* Serve requests on `ctl` until its other end closes (then exit). Returns only in a run, forked for a request, with
   the request's arguments (argv0 first, NULL-terminated; `*argc` of them), its standard output and error the
   request's descriptor. With `domain`, a request must name three files, the first `domain`. */
static char **serve(int ctl, char *argv0, const char *domain, int *argc) {
    for (int i = 0; i < MAX_RUNS; i++) run_out[i] = -1;
    sigset_t chld, old;
    sigemptyset(&chld);
    sigaddset(&chld, SIGCHLD);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = reap;
    sa.sa_flags = SA_RESTART | SA_NOCLDSTOP;
    sigaction(SIGCHLD, &sa, NULL);
    signal(SIGPIPE, SIG_IGN); /* a run's status written after its reader has gone (a cancelled check) */
    pid_t server = getpid();
    static char buf[MAX_REQUEST];
    static char *args[MAX_ARGS + 2];
    write_all(ctl, "R", 1);
    for (;;) {
        union {
            struct cmsghdr h;
            char space[CMSG_SPACE(sizeof(int))];
        } control;
        struct iovec iov = {buf, sizeof buf - 1};
        struct msghdr msg;
        memset(&msg, 0, sizeof msg);
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control.space;
        msg.msg_controllen = sizeof control.space;
        ssize_t n = recvmsg(ctl, &msg, MSG_CMSG_CLOEXEC);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) _exit(0); /* the service closed its end, or died: the runs die with this process */
        buf[n] = '\0';
        int out = -1;
        struct cmsghdr *c = CMSG_FIRSTHDR(&msg);
        if (c && c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_RIGHTS && c->cmsg_len == CMSG_LEN(sizeof(int)))
            memcpy(&out, CMSG_DATA(c), sizeof(int));
        int count = 0, nice_by = 0, fits = 1;
        args[count++] = argv0;
        for (char *p = buf; p < buf + n; p += strlen(p) + 1) {
            if (p == buf) nice_by = atoi(p);
            else if (count <= MAX_ARGS) args[count++] = p;
            else fits = 0;
        }
        args[count] = NULL;
        if (domain != NULL && (count != 4 || strcmp(args[1], domain) != 0)) fits = 0;
        pid_t run = -1;
        sigprocmask(SIG_BLOCK, &chld, &old);
        int slot = -1;
        for (int i = 0; i < MAX_RUNS && slot < 0; i++)
            if (run_pid[i] == 0) slot = i;
        if (out >= 0 && count > 1 && fits && slot >= 0 && (msg.msg_flags & (MSG_TRUNC | MSG_CTRUNC)) == 0) {
            run = fork();
            if (run == 0) { /* the run: VAL's own start-up and main, or the rest of main, on the request's files */
                struct sigaction dfl;
                memset(&dfl, 0, sizeof dfl);
                dfl.sa_handler = SIG_DFL;
                sigaction(SIGCHLD, &dfl, NULL);
                sigaction(SIGPIPE, &dfl, NULL);
                sigprocmask(SIG_SETMASK, &old, NULL);
                prctl(PR_SET_PDEATHSIG, SIGKILL);
                if (getppid() != server) _exit(127);
                setpgid(0, 0);
                if (nice_by > 0) setpriority(PRIO_PROCESS, 0, getpriority(PRIO_PROCESS, 0) + nice_by);
                close(ctl);
                if (dup2(out, 1) < 0 || dup2(out, 2) < 0) _exit(127);
                if (out > 2) close(out);
                *argc = count;
                return args;
            }
            if (run > 0) { /* also here: the group exists when the reply arrives */
                setpgid(run, run);
                run_pid[slot] = run;
                run_out[slot] = out;
                out = -1; /* closed when the run ends, after its status */
            }
        }
        sigprocmask(SIG_SETMASK, &old, NULL);
        if (out >= 0) close(out);
        int reply = (int)run;
        write_all(ctl, (const char *)&reply, sizeof reply);
    }
}

/* Past the domain: the server's descriptor, its domain, the paths that stand for a run's problem and plan; in a
   run, the request's problem and plan. */
static int after_ctl = -1;
static char *after_domain, *after_problem, *after_plan, *run_problem, *run_plan;
static char **val_argv; /* VAL's arguments: a run writes its plan's path over the plan's stand-in, which VAL prints */

typedef FILE *(*fopen_fn)(const char *, const char *);

/* VAL opens a file (`fopen` or `fopen64`, as its C++ library calls it): past the domain, the problem's stand-in is
   where the server serves (a run goes on from here with its own problem), and a run's plan stand-in is its plan. */
static FILE *opened(const char *which, const char *path, const char *mode) {
    fopen_fn real = (fopen_fn)dlsym(RTLD_NEXT, which);
    if (real == NULL) {
        errno = ENOSYS;
        return NULL;
    }
    if (path != NULL && after_problem != NULL) {
        if (run_problem == NULL && after_ctl >= 0 && strcmp(path, after_problem) == 0) {
            int count = 0;
            char **args = serve(after_ctl, val_argv[0], after_domain, &count);
            run_problem = args[2];
            run_plan = args[3];
            if (strlen(run_plan) <= strlen(val_argv[3])) strcpy(val_argv[3], run_plan);
            return real(run_problem, mode);
        }
        if (run_plan != NULL && after_plan != NULL && strcmp(path, after_plan) == 0) return real(run_plan, mode);
    }
    return real(path, mode);
}

FILE *fopen(const char *path, const char *mode) { return opened("fopen", path, mode); }
FILE *fopen64(const char *path, const char *mode) { return opened("fopen64", path, mode); }

int __libc_start_main(main_fn main_, int argc, char **argv, void (*init)(void), void (*fini)(void),
                      void (*rtld_fini)(void), void *stack_end) {
    start_fn real = (start_fn)dlsym(RTLD_NEXT, "__libc_start_main");
    const char *fd = getenv("PLANHRC_VALFORK_FD");
    if (real == NULL) _exit(127);
    if (fd == NULL || *fd == '\0') return real(main_, argc, argv, init, fini, rtld_fini, stack_end);
    int ctl = atoi(fd);
    const char *after = getenv("PLANHRC_VALFORK_AFTER"), *plan = getenv("PLANHRC_VALFORK_PLAN");
    if (after != NULL && *after != '\0') { /* past the domain: VAL's main, served from its problem's open */
        if (argc != 4 || plan == NULL || strcmp(argv[2], after) != 0 || strcmp(argv[3], plan) != 0) _exit(127);
        after_ctl = ctl;
        after_domain = strdup(argv[1]);
        after_problem = strdup(after);
        after_plan = strdup(plan);
        val_argv = argv;
        unsetenv("PLANHRC_VALFORK_FD");
        unsetenv("PLANHRC_VALFORK_AFTER");
        unsetenv("PLANHRC_VALFORK_PLAN");
        if (after_domain == NULL || after_problem == NULL || after_plan == NULL) _exit(127);
        return real(main_, argc, argv, init, fini, rtld_fini, stack_end);
    }
    unsetenv("PLANHRC_VALFORK_FD");
    int count = 0;
    char **args = serve(ctl, argc > 0 ? argv[0] : "Validate", NULL, &count); /* returns in a run only */
    _exit(real(main_, count, args, init, fini, rtld_fini, stack_end));
}
