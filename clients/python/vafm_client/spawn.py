# SPDX-License-Identifier: MIT
"""Start and stop a private vafmd, and the endpoint options every example shares.

    with Daemon("build/src/daemon/vafmd", "--preset", "paper-fig4", "--free-run") as d:
        d.client.curve(index=0)                # d.rep, d.pub: ipc:// endpoints in a private directory

The daemon listens on ipc:// endpoints in a fresh temporary directory, so any number of them run side by
side (tests, CI, the main job) without choosing ports. `stop()` sends `shutdown`, waits for the exit
(killing the process only if it does not exit within 10 s) and removes the directory.
"""
import contextlib
import os
import shutil
import subprocess
import tempfile
import time

from .client import DEFAULT_PUB, DEFAULT_REP, Client, TransportError


class Daemon:
    """A vafmd started here. Attributes: rep, pub (endpoints), client (a connected Client), proc, dir."""

    def __init__(self, vafmd, *args, curve=None, start_timeout=10.0, log=None):
        self.dir = tempfile.mkdtemp(prefix="vafmd-")
        self.rep, self.pub = f"ipc://{self.dir}/rep", f"ipc://{self.dir}/pub"
        self._log = open(log, "w") if log else subprocess.DEVNULL
        self.proc = subprocess.Popen([vafmd, "--rep", self.rep, "--pub", self.pub, *args],
                                     stdout=self._log, stderr=subprocess.PIPE)
        deadline = time.monotonic() + start_timeout
        self.client = None
        try:
            while True:  # the first hello may race the bind; the client reopens its socket after a timeout
                self.client = Client(self.rep, timeout=0.5, curve=curve)
                try:
                    self.client.hello()
                    break
                except TransportError:
                    self.client.close()
                    self.client = None
                    if self.proc.poll() is not None:
                        raise RuntimeError(f"vafmd exited with status {self.proc.returncode}: "
                                           f"{self.proc.stderr.read().decode(errors='replace').strip()}")
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"vafmd did not answer hello within {start_timeout} s")
        except BaseException:
            self.stop()
            raise
        self.client.timeout = 20.0

    def stop(self):
        """Shut the daemon down; return its exit status."""
        if self.proc.poll() is None and self.client is not None:
            try:
                self.client.shutdown()
            except (TransportError, Exception):  # noqa: BLE001 (already gone: wait/kill below)
                pass
        if self.client is not None:
            self.client.close()
            self.client = None
        try:
            rc = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        self.stderr = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
        if self.proc.stderr:
            self.proc.stderr.close()
        if self._log is not subprocess.DEVNULL:
            self._log.close()
            self._log = subprocess.DEVNULL
        shutil.rmtree(self.dir, ignore_errors=True)
        return rc

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def add_endpoint_args(ap):
    """The options of every example: --rep/--pub of a running daemon, or --spawn PATH to start one."""
    g = ap.add_argument_group("daemon")
    g.add_argument("--rep", default=DEFAULT_REP, help="command endpoint of a running vafmd (default %(default)s)")
    g.add_argument("--pub", default=DEFAULT_PUB, help="stream endpoint (default %(default)s)")
    g.add_argument("--spawn", metavar="VAFMD", help="start this vafmd on private ipc:// endpoints, stop it at the end")
    g.add_argument("--spawn-arg", action="append", default=[], metavar="ARG",
                   help="extra argument for the spawned vafmd (repeat), e.g. --spawn-arg=--free-run")
    return ap


@contextlib.contextmanager
def connect(a):
    """(client, rep, pub) for parsed endpoint options; a spawned daemon is stopped on exit."""
    if a.spawn:
        if not os.access(a.spawn, os.X_OK):
            raise SystemExit(f"--spawn {a.spawn}: not an executable (build it first: ninja -C build)")
        d = Daemon(a.spawn, *a.spawn_arg)
        print(f"started {a.spawn} {' '.join(a.spawn_arg)} (pid {d.proc.pid}) on {d.rep}, {d.pub}".replace("  ", " "),
              flush=True)
        try:
            yield d.client, d.rep, d.pub
        finally:
            rc = d.stop()
            print(f"stopped vafmd (exit status {rc})", flush=True)
    else:
        with Client(a.rep) as c:
            yield c, a.rep, a.pub


def plt_agg():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_png(fig, path, dpi=110, say="PNG: {}"):
    """Lay the figure out, write it to path and print where (say, formatted with the path)."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    print(say.format(path))
