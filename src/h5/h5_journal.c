/* SPDX-License-Identifier: MIT */
/*
 * A journaling file driver under HDF5, so that a flush is atomic for a killed process.
 *
 * HDF5 1.10 writes the metadata of a flush in place, in no crash-safe order: a kill during H5Fflush can
 * leave a B-tree node that points into a heap block not yet written, and then even the root group
 * cannot be listed. This driver is the POSIX driver ("sec2") with one change. The bytes [0, committed)
 * are the state of the last completed flush. A write that touches them does not go to the file but to
 * a buffer of 4 KiB pages; writes past `committed` (new raw data, new objects) go straight to the file,
 * where the committed state does not look. At the end of every flush (and at close) the pages are
 * committed:
 *   1. the pages are appended to the file, then a trailer (magic, position, count, CRC-32s);
 *   2. the pages are written in place;
 *   3. the file is cut to HDF5's end of allocation, which removes the journal.
 * Killed before the trailer is complete: the file holds the previous state (HDF5 ignores bytes past its
 * end of allocation). Killed after: the journal is intact and is replayed on the next open (applied by a
 * writer, overlaid in memory by a reader; replaying twice writes the same bytes). Other programs see
 * the previous or the new state, except while step 2 runs (microseconds), until vafm opens the file.
 * Protects against the death of the process, not against power loss (no fsync).
 *
 * The driver class is the HDF5 1.10 one; with another HDF5 the writer falls back to the default driver.
 */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "h5/h5_internal.h"

#define S_PAGE 4096u
#define S_MAGIC "VAFMJNL1"
#define S_TRAILER 48u

/* ---- CRC-32 (IEEE, as zlib) ----------------------------------------------------------------------- */

static uint32_t s_crc_table[256];
static pthread_once_t s_crc_once = PTHREAD_ONCE_INIT;

static void s_crc_init(void)
{
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++)
            c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        s_crc_table[i] = c;
    }
}

static uint32_t s_crc(const unsigned char *p, size_t n)
{
    pthread_once(&s_crc_once, s_crc_init);
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++)
        c = s_crc_table[(c ^ p[i]) & 0xFF] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

static void s_put64(unsigned char *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static uint64_t s_get64(const unsigned char *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = v << 8 | p[i];
    return v;
}

/* ---- page sets ------------------------------------------------------------------------------------ */

typedef struct s_pages {
    uint64_t *idx;        /* page numbers, sorted */
    unsigned char **data; /* S_PAGE bytes each */
    size_t n, cap;
} s_pages;

static void s_pages_free(s_pages *p)
{
    for (size_t i = 0; i < p->n; i++)
        free(p->data[i]);
    free(p->idx);
    free(p->data);
    memset(p, 0, sizeof *p);
}

static size_t s_pages_find(const s_pages *p, uint64_t page, int *found)
{
    size_t lo = vafm_h5i_u64_lower_bound(p->idx, p->n, page);
    *found = lo < p->n && p->idx[lo] == page;
    return lo;
}

static int s_pread_full(int fd, void *buf, size_t n, uint64_t off, uint64_t eof)
{
    /* bytes past the end of the file read as zeros, like the POSIX driver */
    unsigned char *b = buf;
    while (n > 0) {
        if (off >= eof) {
            memset(b, 0, n);
            return 0;
        }
        size_t want = n;
        if (off + want > eof)
            want = (size_t)(eof - off);
        ssize_t got = pread(fd, b, want, (off_t)off);
        if (got < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        if (got == 0) {
            memset(b, 0, n);
            return 0;
        }
        b += got;
        off += (uint64_t)got;
        n -= (size_t)got;
    }
    return 0;
}

_Thread_local int vafm_h5i_io_errno;

static int s_pwrite_full(int fd, const void *buf, size_t n, uint64_t off)
{
    const unsigned char *b = buf;
    while (n > 0) {
        ssize_t put = pwrite(fd, b, n, (off_t)off);
        if (put < 0) {
            if (errno == EINTR)
                continue;
            vafm_h5i_io_errno = errno; /* the cause, for the message (HDF5's own stack loses it) */
            return -1;
        }
        b += put;
        off += (uint64_t)put;
        n -= (size_t)put;
    }
    return 0;
}

/* The page `page`, loaded from the file on first use. */
static unsigned char *s_pages_get(s_pages *p, uint64_t page, int fd, uint64_t eof)
{
    int found;
    size_t at = s_pages_find(p, page, &found);
    if (found)
        return p->data[at];
    if (p->n == p->cap) {
        size_t cap = p->cap ? 2 * p->cap : 32;
        uint64_t *i = realloc(p->idx, cap * sizeof *i);
        if (!i)
            return NULL;
        p->idx = i;
        unsigned char **d = realloc(p->data, cap * sizeof *d);
        if (!d)
            return NULL;
        p->data = d;
        p->cap = cap;
    }
    unsigned char *d = malloc(S_PAGE);
    if (!d || s_pread_full(fd, d, S_PAGE, page * S_PAGE, eof)) {
        free(d);
        return NULL;
    }
    memmove(p->idx + at + 1, p->idx + at, (p->n - at) * sizeof *p->idx);
    memmove(p->data + at + 1, p->data + at, (p->n - at) * sizeof *p->data);
    p->idx[at] = page;
    p->data[at] = d;
    p->n++;
    return d;
}

/* Copy the pages' bytes over buf = file[off, off + n), only below `limit`. */
static void s_pages_overlay(const s_pages *p, unsigned char *buf, uint64_t off, size_t n, uint64_t limit)
{
    if (!p->n || off >= limit)
        return;
    uint64_t end = off + n < limit ? off + n : limit;
    int found;
    for (size_t i = s_pages_find(p, off / S_PAGE, &found); i < p->n && p->idx[i] * S_PAGE < end; i++) {
        uint64_t ps = p->idx[i] * S_PAGE, a = ps > off ? ps : off, b = ps + S_PAGE < end ? ps + S_PAGE : end;
        if (a < b)
            memcpy(buf + (a - off), p->data[i] + (a - ps), (size_t)(b - a));
    }
}

/* ---- the journal at the end of the file ----------------------------------------------------------- */

/* Load a complete journal into pages. @return 1 (loaded; *start = where it begins), 0 (none), −1 (I/O). */
static int s_journal_load(int fd, uint64_t size, s_pages *p, uint64_t *start)
{
    unsigned char t[S_TRAILER];
    if (size < S_TRAILER)
        return 0;
    if (s_pread_full(fd, t, S_TRAILER, size - S_TRAILER, size))
        return -1;
    if (memcmp(t, S_MAGIC, 8) || s_crc(t, 40) != (uint32_t)s_get64(t + 40))
        return 0;
    uint64_t js = s_get64(t + 8), n = s_get64(t + 16), crc = s_get64(t + 32);
    uint64_t len = n * (16 + S_PAGE);
    if (js > size - S_TRAILER || size - S_TRAILER - js != len || n == 0)
        return 0;
    unsigned char *b = malloc((size_t)len);
    if (!b)
        return -1;
    if (s_pread_full(fd, b, (size_t)len, js, size)) {
        free(b);
        return -1;
    }
    int rc = 0;
    if (s_crc(b, (size_t)len) == (uint32_t)crc) {
        rc = 1;
        for (uint64_t i = 0; i < n && rc == 1; i++) {
            const unsigned char *e = b + i * (16 + S_PAGE);
            uint64_t addr = s_get64(e), l = s_get64(e + 8);
            if (addr % S_PAGE || l == 0 || l > S_PAGE || addr + l > js) {
                rc = 0;
                break;
            }
            unsigned char *d = s_pages_get(p, addr / S_PAGE, fd, js);
            if (!d) {
                rc = -1;
                break;
            }
            memcpy(d, e + 16, (size_t)l);
        }
        if (rc != 1)
            s_pages_free(p);
    }
    free(b);
    if (rc == 1)
        *start = js;
    return rc;
}

/* ---- the driver ----------------------------------------------------------------------------------- */

typedef struct s_file {
    H5FD_t pub; /* first: HDF5 casts between the two */
    int fd;
    int rdonly;
    dev_t dev;
    ino_t ino;
    haddr_t eoa;
    uint64_t eof;       /* logical end of file (without a journal being replayed in memory) */
    uint64_t committed; /* [0, committed) is the last committed state */
    s_pages pages;      /* writer: pending pages; reader: a replayed journal */
} s_file;

static void s_push(H5E_major_t maj, H5E_minor_t min, const char *msg)
{
    H5Epush2(H5E_DEFAULT, __FILE__, "vafm journal driver", __LINE__, H5E_ERR_CLS, maj, min, "%s", msg);
}

/* Test hook: a process that sets this dies (_exit) at that step of the next commit with pages:
 * 1 after the pages and before the trailer, 2 after the trailer, 3 halfway through writing in place,
 * 4 before the journal is cut off. 0 (always, outside tests/test_h5.c): off. */
int vafm_h5i_journal_crash_at = 0;

static int s_commit(s_file *f)
{
    uint64_t final = f->eoa != HADDR_UNDEF && f->eoa > 0 ? (uint64_t)f->eoa : f->eof;
    /* The new state's end of allocation must be reachable before anything of it is committed: with the
     * file size limited (EFBIG) a state whose superblock claims more than the file can hold would be
     * "truncated" for every reader, and so would its journal when replayed. Extending first (sparse,
     * no blocks) fails at once where the size is limited; the committed state stays as it was. */
    if (final > f->eof) {
        if (ftruncate(f->fd, (off_t)final)) {
            vafm_h5i_io_errno = errno;
            return -1;
        }
        f->eof = final;
    }
    if (f->pages.n) {
        /* pages clipped to the committed state: bytes past it were written directly */
        size_t n = f->pages.n;
        size_t len = n * (16 + S_PAGE);
        unsigned char *b = calloc(1, len + S_TRAILER);
        if (!b)
            return -1;
        for (size_t i = 0; i < n; i++) {
            unsigned char *e = b + i * (16 + S_PAGE);
            uint64_t addr = f->pages.idx[i] * S_PAGE;
            uint64_t l = addr + S_PAGE <= f->committed ? S_PAGE : f->committed - addr;
            s_put64(e, addr);
            s_put64(e + 8, l);
            memcpy(e + 16, f->pages.data[i], (size_t)l);
        }
        uint64_t js = f->eof > f->committed ? f->eof : f->committed;
        unsigned char *t = b + len;
        memcpy(t, S_MAGIC, 8);
        s_put64(t + 8, js);
        s_put64(t + 16, n);
        s_put64(t + 24, final);
        s_put64(t + 32, s_crc(b, len));
        s_put64(t + 40, s_crc(t, 40));
        /* 1. journal, then its trailer; 2. in place; 3. cut the journal off */
        int rc = s_pwrite_full(f->fd, b, len, js);
        if (vafm_h5i_journal_crash_at == 1)
            _exit(0);
        rc = rc || s_pwrite_full(f->fd, t, S_TRAILER, js + len);
        if (vafm_h5i_journal_crash_at == 2)
            _exit(0);
        for (size_t i = 0; !rc && i < n; i++) {
            if (vafm_h5i_journal_crash_at == 3 && i == n / 2)
                _exit(0);
            const unsigned char *e = b + i * (16 + S_PAGE);
            rc = s_pwrite_full(f->fd, e + 16, (size_t)s_get64(e + 8), s_get64(e));
        }
        free(b);
        if (vafm_h5i_journal_crash_at == 4)
            _exit(0);
        if (rc)
            return -1;
        s_pages_free(&f->pages);
        if (f->eoa == HADDR_UNDEF || f->eoa == 0)
            final = js; /* (HDF5 always has an end of allocation here) */
    }
    if (ftruncate(f->fd, (off_t)final) && (vafm_h5i_io_errno = errno) != 0)
        return -1;
    f->eof = final;
    f->committed = final;
    return 0;
}

static H5FD_t *s_open(const char *name, unsigned flags, hid_t fapl, haddr_t maxaddr)
{
    /* O_TRUNC is not passed to open(): the file is locked first and cut only once the lock is ours, so a
     * file another process writes is never truncated under it (HDF5 takes its lock after the open). */
    int o = ((flags & H5F_ACC_RDWR) ? O_RDWR : O_RDONLY) | O_NONBLOCK | O_CLOEXEC;
    if (flags & H5F_ACC_CREAT)
        o |= O_CREAT;
    if (flags & H5F_ACC_EXCL)
        o |= O_EXCL;
    int fd = open(name, o, 0666);
    if (fd < 0) {
        char msg[300];
        snprintf(msg, sizeof msg, "unable to open file: name = '%s', errno = %d, error message = '%s'", name, errno,
                 strerror(errno));
        s_push(H5E_FILE, H5E_CANTOPENFILE, msg);
        return NULL;
    }
    struct stat st0;
    if (fstat(fd, &st0) || !S_ISREG(st0.st_mode)) {
        close(fd);
        s_push(H5E_FILE, H5E_CANTOPENFILE, "not a regular file");
        return NULL;
    }
    if (flock(fd, ((flags & H5F_ACC_RDWR) ? LOCK_EX : LOCK_SH) | LOCK_NB) && errno != ENOSYS && errno != ENOLCK) {
        close(fd);
        s_push(H5E_FILE, H5E_CANTLOCKFILE, "unable to lock the file (another process has it open)");
        return NULL;
    }
    if ((flags & H5F_ACC_TRUNC) && ftruncate(fd, 0)) {
        char msg[160];
        snprintf(msg, sizeof msg, "unable to truncate the file: %s", strerror(errno));
        close(fd);
        s_push(H5E_FILE, H5E_CANTOPENFILE, msg);
        return NULL;
    }
    struct stat st;
    s_file *f = calloc(1, sizeof *f);
    if (!f || fstat(fd, &st)) {
        free(f);
        close(fd);
        s_push(H5E_FILE, H5E_CANTOPENFILE, "unable to set up the file");
        return NULL;
    }
    f->fd = fd;
    f->rdonly = !(flags & H5F_ACC_RDWR);
    f->dev = st.st_dev;
    f->ino = st.st_ino;
    f->eof = (uint64_t)st.st_size;
    f->eoa = 0;
    uint64_t js = 0;
    int j = s_journal_load(fd, f->eof, &f->pages, &js);
    if (j < 0) {
        s_pages_free(&f->pages);
        close(fd);
        free(f);
        s_push(H5E_FILE, H5E_READERROR, "the journal at the end of the file cannot be read");
        return NULL;
    }
    if (j == 1) {
        /* a flush was killed after its journal was complete: finish it */
        if (!f->rdonly) {
            int rc = 0;
            for (size_t i = 0; !rc && i < f->pages.n; i++) {
                uint64_t addr = f->pages.idx[i] * S_PAGE;
                uint64_t l = addr + S_PAGE <= js ? S_PAGE : js - addr;
                rc = s_pwrite_full(fd, f->pages.data[i], (size_t)l, addr);
            }
            s_pages_free(&f->pages);
            if (rc || ftruncate(fd, (off_t)js)) {
                close(fd);
                free(f);
                s_push(H5E_FILE, H5E_WRITEERROR, "the journal at the end of the file cannot be replayed");
                return NULL;
            }
        }
        f->eof = js; /* a reader keeps the pages as an overlay */
    }
    f->committed = f->eof;
    return &f->pub;
}

/* A failed close (a full disk during the final commit) still releases everything: the committed state
 * [0, committed) is on disk and the uncommitted pages could not be written, so the file holds the last
 * completed flush, as after a kill. HDF5 does not call close again (the library is never shut down at
 * exit, h5_common.c: it would re-close the half-destroyed file and crash). */
static herr_t s_close(H5FD_t *_f)
{
    s_file *f = (s_file *)_f;
    herr_t rc = 0;
    if (!f->rdonly && s_commit(f)) {
        char msg[160];
        snprintf(msg, sizeof msg, "the journal cannot be committed at close: %s", strerror(errno));
        s_push(H5E_IO, H5E_WRITEERROR, msg);
        rc = -1;
    }
    s_pages_free(&f->pages);
    close(f->fd);
    free(f);
    return rc;
}

static int s_cmp(const H5FD_t *_a, const H5FD_t *_b)
{
    const s_file *a = (const s_file *)_a, *b = (const s_file *)_b;
    if (a->dev != b->dev)
        return a->dev < b->dev ? -1 : 1;
    if (a->ino != b->ino)
        return a->ino < b->ino ? -1 : 1;
    return 0;
}

static herr_t s_query(const H5FD_t *f, unsigned long *flags)
{
    /* as sec2; SWMR_IO only unlocks H5Fget_eoa (vafm never opens files for SWMR) */
    if (flags)
        *flags = H5FD_FEAT_AGGREGATE_METADATA | H5FD_FEAT_ACCUMULATE_METADATA | H5FD_FEAT_DATA_SIEVE |
                 H5FD_FEAT_AGGREGATE_SMALLDATA | H5FD_FEAT_POSIX_COMPAT_HANDLE | H5FD_FEAT_SUPPORTS_SWMR_IO;
    return 0;
}

static haddr_t s_get_eoa(const H5FD_t *f, H5FD_mem_t type)
{
    return ((const s_file *)f)->eoa;
}

static herr_t s_set_eoa(H5FD_t *f, H5FD_mem_t type, haddr_t addr)
{
    ((s_file *)f)->eoa = addr;
    return 0;
}

static haddr_t s_get_eof(const H5FD_t *f, H5FD_mem_t type)
{
    return (haddr_t)((const s_file *)f)->eof;
}

static herr_t s_get_handle(H5FD_t *f, hid_t fapl, void **handle)
{
    *handle = &((s_file *)f)->fd;
    return 0;
}

static herr_t s_read(H5FD_t *_f, H5FD_mem_t type, hid_t dxpl, haddr_t addr, size_t size, void *buf)
{
    s_file *f = (s_file *)_f;
    if (addr == HADDR_UNDEF || addr + size < addr) {
        s_push(H5E_IO, H5E_OVERFLOW, "address overflow");
        return -1;
    }
    if (s_pread_full(f->fd, buf, size, addr, f->eof)) {
        s_push(H5E_IO, H5E_READERROR, "read failed");
        return -1;
    }
    s_pages_overlay(&f->pages, buf, addr, size, f->committed);
    return 0;
}

static herr_t s_write(H5FD_t *_f, H5FD_mem_t type, hid_t dxpl, haddr_t addr, size_t size, const void *buf)
{
    s_file *f = (s_file *)_f;
    if (f->rdonly) {
        s_push(H5E_IO, H5E_WRITEERROR, "file opened read-only");
        return -1;
    }
    if (addr == HADDR_UNDEF || addr + size < addr) {
        s_push(H5E_IO, H5E_OVERFLOW, "address overflow");
        return -1;
    }
    const unsigned char *b = buf;
    uint64_t a = addr, end = addr + size;
    /* the part inside the committed state goes to pages */
    while (a < end && a < f->committed) {
        uint64_t page = a / S_PAGE, ps = page * S_PAGE;
        uint64_t stop = ps + S_PAGE;
        if (stop > end)
            stop = end;
        if (stop > f->committed)
            stop = f->committed;
        unsigned char *d = s_pages_get(&f->pages, page, f->fd, f->eof);
        if (!d) {
            s_push(H5E_IO, H5E_WRITEERROR, "out of memory for the journal");
            return -1;
        }
        memcpy(d + (a - ps), b + (a - addr), (size_t)(stop - a));
        a = stop;
    }
    /* the rest is new space: straight to the file */
    if (a < end) {
        if (s_pwrite_full(f->fd, b + (a - addr), (size_t)(end - a), a)) {
            char msg[160];
            snprintf(msg, sizeof msg, "write failed: %s", strerror(errno));
            s_push(H5E_IO, H5E_WRITEERROR, msg);
            return -1;
        }
        if (end > f->eof)
            f->eof = end;
    }
    return 0;
}

static herr_t s_flush(H5FD_t *_f, hid_t dxpl, hbool_t closing)
{
    s_file *f = (s_file *)_f;
    if (f->rdonly)
        return 0;
    if (s_commit(f)) {
        s_push(H5E_IO, H5E_WRITEERROR, "the journal cannot be committed");
        return -1;
    }
    return 0;
}

static herr_t s_truncate(H5FD_t *_f, hid_t dxpl, hbool_t closing)
{
    s_file *f = (s_file *)_f;
    /* extend now; shrinking waits for the commit, which knows whether the cut bytes are still needed */
    if (!f->rdonly && f->eoa != HADDR_UNDEF && (uint64_t)f->eoa > f->eof) {
        if (ftruncate(f->fd, (off_t)f->eoa) && (vafm_h5i_io_errno = errno) != 0) {
            s_push(H5E_IO, H5E_SEEKERROR, "unable to extend the file");
            return -1;
        }
        f->eof = (uint64_t)f->eoa;
    }
    return 0;
}

static herr_t s_lock(H5FD_t *_f, hbool_t rw)
{
    s_file *f = (s_file *)_f;
    if (flock(f->fd, (rw ? LOCK_EX : LOCK_SH) | LOCK_NB)) {
        if (errno == ENOSYS)
            return 0; /* file system without locks */
        s_push(H5E_FILE, H5E_CANTLOCKFILE, "unable to lock the file (another process has it open?)");
        return -1;
    }
    return 0;
}

static herr_t s_unlock(H5FD_t *_f)
{
    s_file *f = (s_file *)_f;
    if (flock(f->fd, LOCK_UN) && errno != ENOSYS) {
        s_push(H5E_FILE, H5E_CANTUNLOCKFILE, "unable to unlock the file");
        return -1;
    }
    return 0;
}

#if H5_VERS_MAJOR == 1 && H5_VERS_MINOR == 10
static const H5FD_class_t s_class = {
    "vafm-journal",       /* name */
    (haddr_t)INT64_MAX,   /* maxaddr */
    H5F_CLOSE_WEAK,       /* fc_degree */
    NULL,                 /* terminate */
    NULL,                 /* sb_size */
    NULL,                 /* sb_encode */
    NULL,                 /* sb_decode */
    0,                    /* fapl_size */
    NULL,                 /* fapl_get */
    NULL,                 /* fapl_copy */
    NULL,                 /* fapl_free */
    0,                    /* dxpl_size */
    NULL,                 /* dxpl_copy */
    NULL,                 /* dxpl_free */
    s_open,               /* open */
    s_close,              /* close */
    s_cmp,                /* cmp */
    s_query,              /* query */
    NULL,                 /* get_type_map */
    NULL,                 /* alloc */
    NULL,                 /* free */
    s_get_eoa,            /* get_eoa */
    s_set_eoa,            /* set_eoa */
    s_get_eof,            /* get_eof */
    s_get_handle,         /* get_handle */
    s_read,               /* read */
    s_write,              /* write */
    s_flush,              /* flush */
    s_truncate,           /* truncate */
    s_lock,               /* lock */
    s_unlock,             /* unlock */
    H5FD_FLMAP_DICHOTOMY, /* fl_map: raw data and metadata use separate free lists, as sec2 */
};

static pthread_mutex_t s_mu = PTHREAD_MUTEX_INITIALIZER;
static hid_t s_driver = -1;

int vafm_h5i_fapl_journal(hid_t fapl)
{
    pthread_mutex_lock(&s_mu);
    /* HDF5 may have been closed and reopened (H5close) since the driver was registered */
    if (s_driver < 0 || H5Iis_valid(s_driver) <= 0)
        s_driver = H5FDregister(&s_class);
    hid_t d = s_driver;
    pthread_mutex_unlock(&s_mu);
    return d < 0 || H5Pset_driver(fapl, d, NULL) < 0 ? -1 : 0;
}
#else
int vafm_h5i_fapl_journal(hid_t fapl)
{
    (void)s_open, (void)s_close, (void)s_cmp, (void)s_query, (void)s_get_eoa, (void)s_set_eoa, (void)s_get_eof;
    (void)s_get_handle, (void)s_read, (void)s_write, (void)s_flush, (void)s_truncate, (void)s_lock, (void)s_unlock;
    return 0; /* another HDF5: the default driver, flushes are not atomic */
}
#endif

int vafm_h5i_journal_overlay(const char *path, unsigned char *buf, uint64_t off, size_t n, void **state)
{
    /* state: the journal pages of path, loaded on first use (NULL: none); n == 0 frees it */
    s_pages *p = *state;
    if (!n) {
        if (p && p != (void *)1) {
            s_pages_free(p);
            free(p);
        }
        *state = NULL;
        return 0;
    }
    if (!p) {
        int fd = open(path, O_RDONLY);
        struct stat st;
        p = calloc(1, sizeof *p);
        uint64_t js = 0;
        if (fd < 0 || !p || fstat(fd, &st) || s_journal_load(fd, (uint64_t)st.st_size, p, &js) != 1) {
            free(p);
            p = (void *)1; /* no journal */
        }
        if (fd >= 0)
            close(fd);
        *state = p;
    }
    if (p != (void *)1)
        s_pages_overlay(p, buf, off, n, UINT64_MAX);
    return 0;
}
