/* Status table, error messages and logging. */
#include "core.h"

#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const status_names[] = {
#define BF__NAME(name, msg) "BF_" #name,
    BF_STATUS_MAP(BF__NAME)
#undef BF__NAME
};
static const char *const status_messages[] = {
#define BF__MSG(name, msg) msg,
    BF_STATUS_MAP(BF__MSG)
#undef BF__MSG
};

const char *bf_status_name(bf_status s)
{
    return (unsigned)s < BF_STATUS_COUNT ? status_names[s] : "BF_UNKNOWN";
}

const char *bf_status_message(bf_status s)
{
    return (unsigned)s < BF_STATUS_COUNT ? status_messages[s] : "unknown status";
}

static _Thread_local char last_error[BF_ERROR_CAP];

bf_status bf_fail(bf_status s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(last_error, sizeof last_error, fmt, ap);
    va_end(ap);
    bf_debug("%s: %s", bf_status_name(s), last_error);
    return s;
}

const char *bf_last_error(void) { return last_error; }
void bf_clear_error(void) { last_error[0] = '\0'; }

/* Read by every thread that logs (bf_parallel_for workers, synth's PNG
 * writer), set lazily from BITFUSE_LOG: atomic, so the first reads may race
 * to compute the same value but never tear. */
static atomic_int log_level = -1;

static bf_log_level log_level_from_env(void)
{
    const char *e = getenv("BITFUSE_LOG");
    if (!e) return BF_LOG_INFO;
    if (!strcmp(e, "debug")) return BF_LOG_DEBUG;
    if (!strcmp(e, "warn")) return BF_LOG_WARN;
    if (!strcmp(e, "error")) return BF_LOG_ERROR;
    if (!strcmp(e, "silent")) return BF_LOG_SILENT;
    return BF_LOG_INFO;
}

void bf_log_set_level(bf_log_level level) { atomic_store(&log_level, (int)level); }

bf_log_level bf_log_get_level(void)
{
    int level = atomic_load(&log_level);
    if (level < 0) {
        /* Only replaces "unset": a concurrent bf_log_set_level wins. */
        int unset = -1;
        level = (int)log_level_from_env();
        if (!atomic_compare_exchange_strong(&log_level, &unset, level)) level = unset;
    }
    return (bf_log_level)level;
}

void bf_log(bf_log_level level, const char *fmt, ...)
{
    static const char *const prefix[] = {"debug: ", "", "warning: ", "error: "};
    if (level < bf_log_get_level() || level >= BF_LOG_SILENT) return;
    /* One fputs per message so lines from threads do not interleave; a
     * message longer than the stack's line (a long path, a quoted error)
     * is formatted again on the heap rather than cut. */
    char line[2048], *heap = NULL;
    size_t head = (size_t)snprintf(line, sizeof line, "bitfuse: %s", prefix[level]);
    va_list ap, again;
    va_start(ap, fmt);
    va_copy(again, ap);
    int k = vsnprintf(line + head, sizeof line - head - 1, fmt, ap);
    va_end(ap);
    char *out = line;
    size_t n = k > 0 ? (size_t)k : 0;
    if (k < 0) n = (size_t)snprintf(line + head, sizeof line - head - 1, "%s", fmt); /* a bad format: the format */
    if (k >= 0 && head + n + 2 > sizeof line && (heap = malloc(head + n + 2)) != NULL) {
        memcpy(heap, line, head);
        vsnprintf(heap + head, n + 1, fmt, again);
        out = heap;
    } else if (head + n + 2 > sizeof line) {
        n = sizeof line - head - 2; /* no memory: cut, and say so */
        memcpy(line + n + head - 3, "...", 3);
    }
    va_end(again);
    out[head + n] = '\n';
    out[head + n + 1] = '\0';
    fputs(out, stderr);
    free(heap);
}

void bf__assert_fail(const char *expr, const char *file, int line)
{
    fprintf(stderr, "bitfuse: assertion failed: %s (%s:%d)\n", expr, file, line);
    fflush(stderr);
    abort();
}
