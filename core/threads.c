/* A fork-join parallel loop over pthreads: enough for the CPU-side tools
 * (synthetic rendering, evaluation). The GPU path never uses it. */
#include "core.h"

#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <unistd.h>

#define BF_MAX_THREADS 64

int bf_thread_count(void)
{
    const char *e = getenv("BITFUSE_THREADS");
    char *end = NULL;
    long n = e ? strtol(e, &end, 10) : 0;
    /* Not a number (main warns): all cores, as when unset. */
    if (!e || end == e || *end) n = sysconf(_SC_NPROCESSORS_ONLN);
    if (n < 1) n = 1;
    if (n > BF_MAX_THREADS) n = BF_MAX_THREADS;
    return (int)n;
}

typedef struct pfor_job {
    void (*fn)(void *ctx, size_t i);
    void *ctx;
    size_t n;
    atomic_size_t next;
} pfor_job;

static void *pfor_worker(void *arg)
{
    pfor_job *job = arg;
    for (;;) {
        size_t i = atomic_fetch_add(&job->next, 1);
        if (i >= job->n) break;
        job->fn(job->ctx, i);
    }
    return NULL;
}

void bf_parallel_for(size_t n, void (*fn)(void *ctx, size_t i), void *ctx)
{
    pfor_job job = {.fn = fn, .ctx = ctx, .n = n};
    atomic_init(&job.next, 0);
    int nt = bf_thread_count();
    if ((size_t)nt > n) nt = (int)n;
    pthread_t th[BF_MAX_THREADS];
    int started = 0;
    for (int k = 1; k < nt; k++) {
        if (bf_thread_start(&th[started], pfor_worker, &job) != 0) break;
        started++;
    }
    pfor_worker(&job); /* the caller works too */
    for (int k = 0; k < started; k++) pthread_join(th[k], NULL);
}

int bf_thread_start(pthread_t *th, void *(*fn)(void *), void *arg)
{
    /* The new thread inherits the creator's mask: block around the create. */
    sigset_t stop, old;
    sigemptyset(&stop);
    sigaddset(&stop, SIGINT);
    sigaddset(&stop, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop, &old);
    int rc = pthread_create(th, NULL, fn, arg);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    return rc;
}
