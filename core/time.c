/* Monotonic time, duration statistics and the per-second progress line. */
#include "core.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

uint64_t bf_time_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

double bf_time_s(void) { return (double)bf_time_ns() * 1e-9; }

bf_status bf_stats_push(bf_stats *s, double x)
{
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 64;
        double *v = realloc(s->v, cap * sizeof *v);
        if (!v) return bf_fail(BF_NO_MEMORY, "statistics: cannot grow to %zu values", cap);
        s->v = v;
        s->cap = cap;
    }
    s->v[s->n++] = x;
    return BF_OK;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

double bf_percentile_inplace(double *v, size_t n, double p)
{
    if (n == 0) return NAN;
    qsort(v, n, sizeof *v, cmp_double);
    double r = p / 100.0 * (double)(n - 1);
    size_t i = (size_t)floor(r);
    if (i + 1 >= n) return v[n - 1];
    double f = r - (double)i;
    return v[i] * (1 - f) + v[i + 1] * f;
}

double bf_stats_percentile(const bf_stats *s, double p)
{
    if (s->n == 0) return NAN;
    double *tmp = malloc(s->n * sizeof *tmp);
    if (!tmp) return NAN;
    for (size_t i = 0; i < s->n; i++) tmp[i] = s->v[i];
    double r = bf_percentile_inplace(tmp, s->n, p);
    free(tmp);
    return r;
}

double bf_stats_mean(const bf_stats *s)
{
    if (s->n == 0) return NAN;
    double sum = 0;
    for (size_t i = 0; i < s->n; i++) sum += s->v[i];
    return sum / (double)s->n;
}

void bf_stats_free(bf_stats *s)
{
    free(s->v);
    s->v = NULL;
    s->n = s->cap = 0;
}

void bf_progress_begin(bf_progress *p, const char *label, uint64_t total)
{
    p->label = label;
    p->total = total;
    p->t_start = p->t_last = bf_time_s();
    const char *e = getenv("BITFUSE_PROGRESS");
    p->enabled = e ? atoi(e) != 0 : isatty(2);
    if (bf_log_get_level() > BF_LOG_INFO) p->enabled = false;
}

static void progress_print(bf_progress *p, uint64_t done, bool final)
{
    double now = bf_time_s(), el = now - p->t_start;
    double rate = el > 0 ? (double)done / el : 0;
    char eta[32] = "";
    if (!final && p->total && rate > 0)
        snprintf(eta, sizeof eta, "  eta %.0f s", (double)(p->total - done) / rate);
    if (p->total)
        fprintf(stderr, "\r%s %llu/%llu (%.0f%%)  %.1f/s%s   %s", p->label, (unsigned long long)done,
                (unsigned long long)p->total, 100.0 * (double)done / (double)p->total, rate, eta,
                final ? "\n" : "");
    else
        fprintf(stderr, "\r%s %llu  %.1f/s   %s", p->label, (unsigned long long)done, rate,
                final ? "\n" : "");
    fflush(stderr);
    p->t_last = now;
}

void bf_progress_update(bf_progress *p, uint64_t done)
{
    if (p->enabled && bf_time_s() - p->t_last >= 1.0) progress_print(p, done, false);
}

void bf_progress_end(bf_progress *p, uint64_t done)
{
    if (p->enabled) progress_print(p, done, true);
}
