# SPDX-License-Identifier: MIT
"""An installed (or packaged) `vafm web` serves the panel: used by test_install.sh and test_deb.sh.

    /usr/bin/python3 web_serves.py VAFM VAFMD BRIDGE

Starts VAFMD on private ipc:// endpoints and `VAFM web` on a free loopback port, then checks: the start line
names BRIDGE (the installed bridge, not the source tree's), an HTTP GET of the page returns its HTML, of
uPlot's JS the library (installed from npm with the panel), of panel.js the page's code; and the bridge's
python3 imports the tune fit from the installed vafm_client (not from the source tree's examples). Prints
one line; exit 0 when all hold, 1 otherwise. The caller sets PYTHONPATH to the installed vafm_client.
"""
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request


def main(vafm, vafmd, bridge):
    tmp = tempfile.mkdtemp(prefix="vafm-web-")
    rep, pub, ready = f"ipc://{tmp}/r", f"ipc://{tmp}/p", os.path.join(tmp, "ready")
    d = subprocess.Popen([vafmd, "--rep", rep, "--pub", pub], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    w = None
    try:
        w = subprocess.Popen([vafm, "web", "--daemon", rep, "--listen", "127.0.0.1:0", "--ready-file", ready],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 30
        while not os.path.exists(ready) and w.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if not os.path.exists(ready):
            w.kill()
            out, err = w.communicate()
            return f"vafm web did not start: {(out + err).decode(errors='replace').strip()[-400:]}"
        url = open(ready).read().strip()
        got = {}
        for path in ("", "vendor/uPlot.iife.min.js", "static/panel.js"):
            with urllib.request.urlopen(url + path, timeout=10) as r:
                got[path] = (r.status, r.read())
        w.terminate()
        out, err = w.communicate(timeout=10)
        w = None
        if f"(bridge {bridge})".encode() not in out:
            return f"the start line does not name {bridge}: {out.decode(errors='replace').strip()}"
        if got[""][0] != 200 or b"<title>" not in got[""][1] or b"vendor/uPlot.iife.min.js" not in got[""][1]:
            return f"the page: {got[''][0]} {got[''][1][:200]!r}"
        js = got["vendor/uPlot.iife.min.js"][1]
        if b"uPlot" not in js or len(js) < 20000:
            return f"uPlot's JS: {len(js)} bytes"
        if b"vafmPanel" not in got["static/panel.js"][1]:
            return "panel.js is not the page's code"
        fit = subprocess.run(["/usr/bin/python3", "-c", "import vafm_client.tune as t; print(t.__file__)"],
                             capture_output=True, text=True, timeout=30)
        if fit.returncode or not fit.stdout.startswith(os.environ.get("PYTHONPATH", "//")):
            return f"the tune fit is not the installed package's: {fit.stdout}{fit.stderr}"
        return f"ok: {url} serves the page, uPlot ({len(js)} bytes) and panel.js from {bridge}"
    finally:
        if w is not None:
            w.kill()
            w.wait()
        d.terminate()
        d.wait(10)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    msg = main(*sys.argv[1:4])
    print(msg)
    sys.exit(0 if msg.startswith("ok:") else 1)
