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
   Without PLANHRC_VALFORK_FD the library does nothing: `Validate` runs as usual. */
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

static int serve(start_fn real, main_fn main_, char *argv0, int ctl, void (*init)(void), void (*fini)(void),
                 void (*rtld_fini)(void), void *stack_end) {
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
        char *argv[MAX_ARGS + 2];
        int argc = 0, nice_by = 0, fits = 1;
        argv[argc++] = argv0;
        for (char *p = buf; p < buf + n; p += strlen(p) + 1) {
            if (p == buf) nice_by = atoi(p);
            else if (argc <= MAX_ARGS) argv[argc++] = p;
            else fits = 0;
        }
        argv[argc] = NULL;
        pid_t run = -1;
        sigprocmask(SIG_BLOCK, &chld, &old);
        int slot = -1;
        for (int i = 0; i < MAX_RUNS && slot < 0; i++)
            if (run_pid[i] == 0) slot = i;
        if (out >= 0 && argc > 1 && fits && slot >= 0 && (msg.msg_flags & (MSG_TRUNC | MSG_CTRUNC)) == 0) {
            run = fork();
            if (run == 0) { /* the run: VAL's own start-up and main, on the request's arguments */
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
                _exit(real(main_, argc, argv, init, fini, rtld_fini, stack_end));
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

int __libc_start_main(main_fn main_, int argc, char **argv, void (*init)(void), void (*fini)(void),
                      void (*rtld_fini)(void), void *stack_end) {
    start_fn real = (start_fn)dlsym(RTLD_NEXT, "__libc_start_main");
    const char *fd = getenv("PLANHRC_VALFORK_FD");
    if (real == NULL) _exit(127);
    if (fd == NULL || *fd == '\0') return real(main_, argc, argv, init, fini, rtld_fini, stack_end);
    int ctl = atoi(fd);
    unsetenv("PLANHRC_VALFORK_FD");
    return serve(real, main_, argc > 0 ? argv[0] : "Validate", ctl, init, fini, rtld_fini, stack_end);
}
