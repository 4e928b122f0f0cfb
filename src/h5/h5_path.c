/* SPDX-License-Identifier: MIT */
/*
 * The path of an HDF5 file, checked before HDF5 touches it: a regular file (not a directory, FIFO,
 * socket or device), not in use by another process (HDF5 and the journal driver hold a flock while a
 * file is open: exclusive for a writer, shared for readers; the holder is named from /proc/locks), and
 * writable when it is to be written, so that a file vafm may not write is called read-only, never
 * damaged, and a file in use is never truncated or resumed under its writer.
 */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include "h5/h5_internal.h"

/* The process holding a flock on (dev, ino), from /proc/locks ("1: FLOCK  ADVISORY  WRITE 123 fd:01:456 0 EOF").
 * @return its pid, or 0 when it cannot be told. */
static long s_lock_holder(dev_t dev, ino_t ino)
{
    FILE *f = fopen("/proc/locks", "re");
    if (!f)
        return 0;
    char line[256];
    long pid = 0;
    while (!pid && fgets(line, sizeof line, f)) {
        char kind[16], adv[16], mode[16];
        long p;
        unsigned maj, min;
        unsigned long long i;
        if (sscanf(line, "%*s %15s %15s %15s %ld %x:%x:%llu", kind, adv, mode, &p, &maj, &min, &i) == 7 &&
            !strcmp(kind, "FLOCK") && i == (unsigned long long)ino && maj == major(dev) && min == minor(dev))
            pid = p;
    }
    fclose(f);
    return pid;
}

int vafm_h5i_errno_denied(int en)
{
    return en == EACCES || en == EPERM || en == EROFS;
}

const char *vafm_h5i_denied_why(int en)
{
    return en == EROFS ? "the file system is mounted read-only"
           : en == EPERM ? "permission denied (operation not permitted: an immutable file or directory?)"
                         : "permission denied";
}

int vafm_h5i_check_dir_writable(const char *path, vafm_error *err)
{
    char dir[4096];
    if (snprintf(dir, sizeof dir, "%s", path) >= (int)sizeof dir)
        return 0; /* too long to check here: the create names it */
    char *slash = strrchr(dir, '/');
    if (slash)
        *(slash == dir ? slash + 1 : slash) = '\0';
    else
        snprintf(dir, sizeof dir, ".");
    if (access(dir, W_OK | X_OK) == 0 || !vafm_h5i_errno_denied(errno))
        return 0; /* any other failure: the create says what it is */
    int en = errno;
    vafm_h5i_err(err, VAFM_EACCES, "", "%s: cannot be created in %s: %s", path, dir, vafm_h5i_denied_why(en));
    return VAFM_EACCES;
}

int vafm_h5i_check_path(const char *path, int for_write, vafm_error *err)
{
    struct stat st;
    if (stat(path, &st))
        return 0; /* absent: the caller says what that means */
    if (!S_ISREG(st.st_mode)) {
        vafm_h5i_err(err, VAFM_EIO, "", "%s: is not a regular file (%s); refused", path,
                     S_ISDIR(st.st_mode) ? "a directory" : S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISSOCK(st.st_mode) ? "a socket"
                                                                                                             : "a device");
        return VAFM_EIO;
    }
    /* HDF5 (and vafm's journal driver) hold a flock while a file is open: exclusive for a writer, shared
     * for readers. Probe it before HDF5 touches the file, so that a file another process writes is named
     * as such (not "damaged") and is never truncated or resumed under it. */
    /* a writer opens it for writing here: a file it may not write (mode, read-only mount, immutable) is
     * named as such, never called damaged (a reader would say "conformance ok") */
    int fd = open(path, (for_write ? O_RDWR : O_RDONLY) | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
        int en = errno;
        if (vafm_h5i_errno_denied(en)) {
            vafm_h5i_err(err, VAFM_EACCES, "", "%s: cannot be opened for writing: %s; the file was not examined "
                         "and is left untouched", path, vafm_h5i_denied_why(en));
            return VAFM_EACCES;
        }
        vafm_h5i_err(err, VAFM_EIO, "", "%s: cannot open: %s", path, strerror(en));
        return VAFM_EIO;
    }
    int rc = 0;
    if (flock(fd, (for_write ? LOCK_EX : LOCK_SH) | LOCK_NB) == 0)
        flock(fd, LOCK_UN);
    else if (errno == EWOULDBLOCK) {
        long pid = s_lock_holder(st.st_dev, st.st_ino);
        char who[96] = "another process";
        if (pid == (long)getpid())
            snprintf(who, sizeof who, "this process itself");
        else if (pid > 0) {
            char comm[32] = "", cp[64];
            snprintf(cp, sizeof cp, "/proc/%ld/comm", pid);
            FILE *c = fopen(cp, "re");
            if (c) {
                if (fgets(comm, sizeof comm, c))
                    comm[strcspn(comm, "\n")] = 0;
                fclose(c);
            }
            snprintf(who, sizeof who, "another process (pid %ld%s%s)", pid, comm[0] ? ", " : "", comm);
        }
        vafm_h5i_err(err, VAFM_ESTATE, "", "%s: is in use by %s, which has it open%s; wait until it has closed "
                     "it%s", path, who, for_write ? "" : " for writing", for_write ? " (it was left untouched)" : "");
        rc = VAFM_ESTATE;
    }
    close(fd);
    return rc;
}
