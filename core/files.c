/* Whole-file reads, atomic writes, directories and strict number parsing. */
#include "core.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

bf_status bf_read_file(const char *path, char **data, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return bf_fail(BF_IO, "%s: cannot open: %s", path, strerror(errno));
    char *buf = NULL;
    size_t n = 0, cap = 0;
    for (;;) {
        if (cap - n < 65536) {
            size_t nc = cap ? 2 * cap : 65536;
            char *nb = realloc(buf, nc + 1);
            if (!nb) {
                free(buf);
                fclose(f);
                return bf_fail(BF_NO_MEMORY, "%s: file too large to read", path);
            }
            buf = nb;
            cap = nc;
        }
        errno = 0;
        size_t r = fread(buf + n, 1, cap - n, f);
        n += r;
        if (r == 0) break;
    }
    int err = ferror(f) ? (errno ? errno : EIO) : 0; /* a folder opens but reads EISDIR */
    fclose(f);
    if (err) {
        free(buf);
        return bf_fail(BF_IO, "%s: cannot read: %s", path, strerror(err));
    }
    buf[n] = '\0';
    *data = buf;
    if (size) *size = n;
    return BF_OK;
}

bf_status bf_mkdir_p(const char *path)
{
    char tmp[4096];
    size_t len = strlen(path);
    if (len == 0) return bf_fail(BF_INVALID_ARG, "an empty folder path");
    if (len >= sizeof tmp)
        return bf_fail(BF_INVALID_ARG, "%.60s...: a folder path of %zu characters is too long (at most %zu)", path, len,
                       sizeof tmp - 1);
    memcpy(tmp, path, len + 1);
    for (char *p = tmp + 1; *p; p++) {
        if (*p != '/') continue;
        *p = '\0';
        if (mkdir(tmp, 0755) != 0 && errno != EEXIST)
            return bf_fail(BF_WRITE, "%s: cannot create directory: %s", tmp, strerror(errno));
        *p = '/';
    }
    if (mkdir(tmp, 0755) != 0 && errno != EEXIST)
        return bf_fail(BF_WRITE, "%s: cannot create directory: %s", tmp, strerror(errno));
    struct stat st;
    if (stat(tmp, &st) != 0 || !S_ISDIR(st.st_mode))
        return bf_fail(BF_WRITE, "%s: exists and is not a directory", tmp);
    return BF_OK;
}

/* ------------------------------------------------------------ outputs */

/* The kernel's protected_symlinks rule: in a sticky, world-writable folder
 * (/tmp) a link is followed only when the follower or the folder's owner
 * owns it. Resolving a link and renaming onto its target would otherwise
 * let another user's planted link choose what is replaced. */
static bool link_may_be_followed(const char *link, const struct stat *ls)
{
    char dir[4096];
    const char *slash = strrchr(link, '/');
    if (!slash) snprintf(dir, sizeof dir, ".");
    else snprintf(dir, sizeof dir, "%.*s", slash == link ? 1 : (int)(slash - link), link);
    struct stat ds;
    if (stat(dir, &ds) != 0) return false;
    bool shared = (ds.st_mode & S_ISVTX) && (ds.st_mode & S_IWOTH);
    return !shared || ls->st_uid == geteuid() || ls->st_uid == ds.st_uid;
}

bf_status bf_link_target(const char *path, char *out, size_t cap)
{
    char cur[4096];
    if (snprintf(cur, sizeof cur, "%s", path) >= (int)sizeof cur) return bf_fail(BF_INVALID_ARG, "path too long: %s", path);
    /* Link by link (at most 40, the kernel's own bound): a chain whose last
     * target does not exist yet ends at that target's name. */
    for (int hop = 0;; hop++) {
        struct stat st;
        if (lstat(cur, &st) != 0 || !S_ISLNK(st.st_mode)) break;
        if (hop == 40) return bf_fail(BF_WRITE, "%s: too many levels of symbolic links", path);
        if (!link_may_be_followed(cur, &st))
            return bf_fail(BF_WRITE, "%s: a symbolic link another user owns in a shared folder: not followed", cur);
        char target[4096];
        ssize_t n = readlink(cur, target, sizeof target - 1);
        if (n < 0) return bf_fail(BF_WRITE, "%s: cannot read the link: %s", cur, strerror(errno));
        target[n] = '\0';
        const char *slash = strrchr(cur, '/');
        int dir = target[0] == '/' || !slash ? 0 : (int)(slash - cur + 1);
        char next[4096];
        if (snprintf(next, sizeof next, "%.*s%s", dir, cur, target) >= (int)sizeof next)
            return bf_fail(BF_INVALID_ARG, "%s: the link's target's path is too long", path);
        memcpy(cur, next, sizeof cur);
    }
    if (snprintf(out, cap, "%s", cur) >= (int)cap) return bf_fail(BF_INVALID_ARG, "%s: the link's target's path is too long", path);
    return BF_OK;
}

/* A slot is claimed (FREE -> FILLING) by one thread, filled, then published
 * (READY); the signal handler takes READY slots (-> REMOVING, never reused,
 * the program is ending) before it reads their paths, so it never reads a
 * path being written or refilled. Forgetting moves READY back to FREE
 * before the file is renamed or removed: a signal between the two leaves
 * that one file. Writers register a path before creating the file. */
enum { PENDING_FREE, PENDING_FILLING, PENDING_READY, PENDING_REMOVING };
/* The path is a copy on the heap, made before the slot is claimed and freed
 * after it is given back (never by the handler): a store write holds one
 * slot per file it has staged. */
static struct {
    atomic_int state;
    char *path;
} g_pending[BF_PENDING_MAX];

int bf_pending_add(const char *path)
{
    size_t n = strlen(path);
    char *copy = malloc(n + 1); /* not bf_malloc: no fault point of its own */
    if (!copy) return -1;
    memcpy(copy, path, n + 1);
    for (int i = 0; i < BF_PENDING_MAX; i++) {
        int want = PENDING_FREE;
        if (!atomic_compare_exchange_strong(&g_pending[i].state, &want, PENDING_FILLING)) continue;
        g_pending[i].path = copy;
        atomic_store(&g_pending[i].state, PENDING_READY);
        return i;
    }
    free(copy);
    return -1;
}

void bf_pending_forget(int *slot)
{
    int want = PENDING_READY;
    if (*slot >= 0 && *slot < BF_PENDING_MAX) {
        /* Read while READY (only its owner forgets a slot): once FREE another
         * thread may claim it and set its own path. Taken by the handler
         * (REMOVING), the copy stays: the program is ending. */
        char *p = g_pending[*slot].path;
        if (atomic_compare_exchange_strong(&g_pending[*slot].state, &want, PENDING_FREE)) free(p);
    }
    *slot = -1;
}

void bf_pending_remove_all(void)
{
    for (int i = 0; i < BF_PENDING_MAX; i++) {
        int want = PENDING_READY;
        if (atomic_compare_exchange_strong(&g_pending[i].state, &want, PENDING_REMOVING)) unlink(g_pending[i].path);
    }
}

bf_status bf_out_open(bf_out *o, const char *path_given)
{
    memset(o, 0, sizeof *o);
    o->fd = -1;
    o->pending = -1;
    /* A symbolic link is written through (bf_link_target): the rename
     * replaces the file it names, not the link. */
    char path[sizeof o->path];
    bf_status sl = bf_link_target(path_given, path, sizeof path);
    if (sl != BF_OK) return sl;
    if (snprintf(o->path, sizeof o->path, "%s", path) >= (int)sizeof o->path ||
        snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%d", path, (int)getpid()) >= (int)sizeof o->tmp)
        return bf_fail(BF_INVALID_ARG, "path too long: %s", path);
    /* The rename would replace what is there: a device node, a pipe or a
     * socket (an --out of /dev/null, a FIFO) is no file to write over. */
    struct stat st;
    bool exists = stat(path, &st) == 0;
    if (exists && !S_ISREG(st.st_mode))
        return bf_fail(BF_WRITE, "%s: exists and is not a regular file (%s)", path,
                       S_ISDIR(st.st_mode) ? "a folder" : "a device, pipe or socket");
    o->pending = bf_pending_add(o->tmp); /* before the file exists: a signal in between removes nothing */
    o->fd = open(o->tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (o->fd < 0) {
        int e = errno;
        bf_pending_forget(&o->pending);
        if (e == ENOENT) /* the name of the folder, not of the temporary file */
            return bf_fail(BF_WRITE, "%s: cannot create: its folder does not exist", path);
        return bf_fail(BF_WRITE, "%s: cannot create %s: %s", path, o->tmp, strerror(e));
    }
    /* The file replaced keeps its permission bits (best effort: the new
     * file is the writer's, as any file it makes). */
    if (exists) (void)fchmod(o->fd, st.st_mode & 07777);
    return BF_OK;
}

/* Hands p[0..n) to the file, continuing short writes. */
static void out_put(bf_out *o, const char *p, size_t n)
{
    while (n > 0 && !o->err) {
        ssize_t w = write(o->fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            o->err = w < 0 && errno ? errno : EIO;
            o->op = "write";
            return;
        }
        p += w;
        n -= (size_t)w;
        o->bytes += (uint64_t)w;
    }
}

void bf_out_flush(bf_out *o)
{
    if (o->n && !o->err) out_put(o, o->buf, o->n);
    o->n = 0;
}

void bf_out_write(bf_out *o, const void *p, size_t n)
{
    if (o->err || o->fd < 0) return;
    if (!o->buf && !(o->buf = malloc(BF_OUT_BUFFER))) {
        o->err = ENOMEM, o->op = "buffer";
        return;
    }
    if (o->n + n > BF_OUT_BUFFER) bf_out_flush(o);
    if (n >= BF_OUT_BUFFER) {
        out_put(o, p, n);
        return;
    }
    memcpy(o->buf + o->n, p, n);
    o->n += n;
}

void bf_out_printf(bf_out *o, const char *fmt, ...)
{
    char line[1024];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    if (n < 0) return;
    if ((size_t)n < sizeof line) {
        bf_out_write(o, line, (size_t)n);
        return;
    }
    char *big = malloc((size_t)n + 1);
    if (!big) {
        if (!o->err) o->err = ENOMEM, o->op = "format";
        return;
    }
    va_start(ap, fmt);
    vsnprintf(big, (size_t)n + 1, fmt, ap);
    va_end(ap);
    bf_out_write(o, big, (size_t)n);
    free(big);
}

void bf_out_abort(bf_out *o)
{
    if (o->fd >= 0) {
        close(o->fd);
        bf_pending_forget(&o->pending);
        unlink(o->tmp);
    }
    o->fd = -1;
    free(o->buf);
    o->buf = NULL;
}

/* Flush, fsync and close: the temporary file whole on disk, or o->err. */
static void out_finish(bf_out *o)
{
    bf_out_flush(o);
    if (!o->err && fsync(o->fd) != 0) o->err = errno, o->op = "fsync";
    /* Close even after a failure, or the descriptor leaks; a failed close
     * can be the first report of a lost write (NFS, quotas). */
    if (close(o->fd) != 0 && !o->err) o->err = errno, o->op = "close";
    o->fd = -1;
    free(o->buf);
    o->buf = NULL;
}

static bf_status out_failed(bf_out *o)
{
    return bf_fail(BF_WRITE, "%s: %s failed: %s", o->path, o->op, strerror(o->err));
}

static bf_status out_rename(bf_out *o)
{
    bf_pending_forget(&o->pending);
    if (rename(o->tmp, o->path) != 0) {
        int e = errno;
        unlink(o->tmp);
        return bf_fail(BF_WRITE, "%s: cannot rename into place: %s", o->path, strerror(e));
    }
    return BF_OK;
}

bf_status bf_out_commit_both(bf_out *first, bf_out *second)
{
    if (first->fd < 0 || second->fd < 0) {
        bf_out *closed = first->fd < 0 ? first : second;
        bf_out_abort(first);
        bf_out_abort(second);
        return bf_fail(BF_WRITE, "%s: the output was not opened", closed->path);
    }
    /* The file that failed first is the cause: an output that filled the
     * disk while it was written leaves the other none to finish in. */
    bool second_failed_first = second->err && !first->err;
    out_finish(first);
    out_finish(second);
    if (first->err || second->err) {
        bf_pending_forget(&first->pending);
        bf_pending_forget(&second->pending);
        unlink(first->tmp);
        unlink(second->tmp);
        return out_failed(first->err && !second_failed_first ? first : second);
    }
    bf_status s = out_rename(first);
    if (s != BF_OK) {
        bf_pending_forget(&second->pending);
        unlink(second->tmp);
        return s;
    }
    return out_rename(second);
}

bf_status bf_out_commit(bf_out *o)
{
    if (o->fd < 0) return bf_fail(BF_WRITE, "%s: the output was not opened", o->path);
    out_finish(o);
    if (o->err) {
        bf_pending_forget(&o->pending);
        unlink(o->tmp);
        return out_failed(o);
    }
    return out_rename(o);
}

bf_status bf_sync_dir(const char *dir)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return bf_fail(BF_WRITE, "%s: cannot open the folder: %s", dir, strerror(errno));
    bf_status s = BF_OK;
    /* A file system that cannot sync a folder says so (EINVAL, ENOTSUP):
     * nothing to do there. */
    if (fsync(fd) != 0 && errno != EINVAL && errno != ENOTSUP && errno != EROFS)
        s = bf_fail(BF_WRITE, "%s: fsync of the folder failed: %s", dir, strerror(errno));
    close(fd);
    return s;
}

bf_status bf_sync_parent(const char *path)
{
    char dir[4096];
    const char *slash = strrchr(path, '/');
    if (!slash) return bf_sync_dir(".");
    size_t n = slash == path ? 1 : (size_t)(slash - path);
    if (n >= sizeof dir) return bf_fail(BF_INVALID_ARG, "%s: path too long", path);
    memcpy(dir, path, n);
    dir[n] = 0;
    return bf_sync_dir(dir);
}

bf_status bf_write_file_atomic(const char *path, const void *data, size_t size)
{
    bf_out o;
    bf_status s = bf_out_open(&o, path);
    if (s != BF_OK) return s;
    /* Straight to the file: no copy into the buffer. */
    out_put(&o, data, size);
    return bf_out_commit(&o);
}

size_t bf_bom_bytes(const char *text, size_t len)
{
    return len >= 3 && (unsigned char)text[0] == 0xEF && (unsigned char)text[1] == 0xBB &&
                   (unsigned char)text[2] == 0xBF
               ? 3
               : 0;
}

size_t bf_trailing_text(const char *text, size_t len, const char *end)
{
    size_t i = end && end >= text && end <= text + len ? (size_t)(end - text) : 0;
    while (i < len && (text[i] == ' ' || text[i] == '\t' || text[i] == '\n' || text[i] == '\r' || text[i] == '\0')) i++;
    return i;
}

bool bf_file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

bf_status bf_path_join(char *out, size_t cap, const char *dir, const char *name)
{
    int n;
    if (!dir || !dir[0] || name[0] == '/')
        n = snprintf(out, cap, "%s", name);
    else
        n = snprintf(out, cap, "%s%s%s", dir, dir[strlen(dir) - 1] == '/' ? "" : "/", name);
    if (n < 0 || (size_t)n >= cap) return bf_fail(BF_INVALID_ARG, "path too long: %s/%s", dir, name);
    return BF_OK;
}

bool bf_parse_double(const char *s, double *out)
{
    if (!s || !*s) return false;
    /* Decimal only: strtod would also read hexadecimal ("0x10"), which no
     * file or option of ours means. */
    if (strchr(s, 'x') || strchr(s, 'X')) return false;
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v)) return false;
    *out = v;
    return true;
}

bool bf_parse_u32(const char *s, uint32_t *out)
{
    if (!s || !*s || *s == '-' || *s == '+') return false;
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (end == s || *end != '\0' || errno == ERANGE || v > UINT32_MAX) return false;
    *out = (uint32_t)v;
    return true;
}

const char *bf_fmt_double(char buf[BF_FMT_DOUBLE_CAP], double v)
{
    for (int digits = 15; digits <= 17; digits++) {
        snprintf(buf, BF_FMT_DOUBLE_CAP, "%.*g", digits, v);
        if (strtod(buf, NULL) == v || v != v) break; /* NaN never compares equal */
    }
    return buf;
}
