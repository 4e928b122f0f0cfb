# SPDX-License-Identifier: MIT
"""The pytest plugin of vafm_client (issue #30), tested on pytest runs of small test files (pytester): each
check is something the plugin must catch or provide. $VAFMD is the daemon; PYTHONPATH has clients/python."""
import os
import re

VAFMD = os.path.abspath(os.environ["VAFMD"])
# the runs under test start in other folders: the client's folder as an absolute path
os.environ["PYTHONPATH"] = os.pathsep.join(os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p)
pytest_plugins = ["pytester"]


def run(pytester, src, *args, **files):
    pytester.makepyfile(test_it=src, **files)
    return pytester.runpytest_subprocess("-p", "vafm_client.pytest_plugin", "-p", "no:cacheprovider",
                                         f"--vafmd={VAFMD}", *args)


def pids_gone(text):
    pids = [int(p) for p in re.findall(r"PID (\d+)", text)]
    assert pids, text
    for p in pids:
        try:
            os.kill(p, 0)
        except ProcessLookupError:
            continue
        raise AssertionError(f"vafmd pid {p} still runs after the test run")


def test_a_daemon_per_test_stopped_after_it(pytester):
    r = run(pytester, """
def test_one(vafmd, vafm_client, vafm_stream):
    run_id = vafm_client.curve(index=0)["run_id"]
    assert vafm_stream.run(run_id).complete
    print("PID", vafmd.proc.pid)
def test_two(vafmd):
    print("PID", vafmd.proc.pid)
    assert vafmd.client.status()["runs_started"] == 0      # a fresh daemon
""", "-s")
    r.assert_outcomes(passed=2)
    out = r.stdout.str()
    assert len(set(re.findall(r"PID (\d+)", out))) == 2
    pids_gone(out)


def test_module_share(pytester):
    r = run(pytester, """
import pytest
pytestmark = pytest.mark.vafm(share="module", preset="paper-fig4")
def test_one(vafmd):
    print("PID", vafmd.proc.pid)
def test_two(vafmd):
    print("PID", vafmd.proc.pid)
    assert vafmd.client.get("k_N_per_m")["k_N_per_m"] == 1.6    # the marker's preset
""", "-s")
    r.assert_outcomes(passed=2)
    assert len(set(re.findall(r"PID (\d+)", r.stdout.str()))) == 1
    pids_gone(r.stdout.str())


def test_an_unexpected_exit_status_fails_teardown(pytester):
    src = """
def test_killed(vafmd, vafm_faults, vafm_stream):
    vafm_faults(script=[{"kind": "kill", "run": 1, "block": 2, "status": 7}])
    vafmd.client.curve(index=0)
    vafmd.proc.wait(20)
    %s
"""
    r = run(pytester, src % "pass")
    r.assert_outcomes(passed=1, errors=1)
    r.stdout.fnmatch_lines(["*vafmd exited with status 7, expected 0*"])
    run(pytester, src % "vafmd.expect_exit(7)").assert_outcomes(passed=1)


def test_a_failed_test_carries_the_daemons_stderr(pytester):
    r = run(pytester, """
def test_fails(vafmd):
    assert False
""")
    r.assert_outcomes(failed=1)
    r.stdout.fnmatch_lines(["*vafmd stderr (pid *", "vafmd *: commands on ipc://*"])


def test_no_vafmd_fails_or_skips_with_the_reason(pytester, monkeypatch):
    monkeypatch.setenv("VAFMD", "/nonexistent/vafmd")
    pytester.makepyfile(test_it="""
import pytest
def test_needs(vafmd):
    pass
@pytest.mark.skip_without_vafmd
def test_optional(vafmd):
    pass
""")
    r = pytester.runpytest_subprocess("-p", "vafm_client.pytest_plugin", "-p", "no:cacheprovider", "-rs")
    r.assert_outcomes(errors=1, skipped=1)
    r.stdout.fnmatch_lines(["*$VAFMD=/nonexistent/vafmd is not an executable file*"])
    r = pytester.runpytest_subprocess("-p", "vafm_client.pytest_plugin", "--vafmd", "/nonexistent/vafmd")
    assert r.ret == 4  # a usage error: an explicit path is required
    r.stderr.fnmatch_lines(["*--vafmd /nonexistent/vafmd: not an executable file*"])


def test_long_tmp_path_and_tcp(pytester):
    deep = pytester.path / ("d" * 60) / ("e" * 60)
    deep.parent.mkdir()
    src = """
import os
def test_it(vafmd):
    path = vafmd.rep.split("://", 1)[1]
    assert vafmd.rep.startswith("%s") and len(os.fsencode(path)) <= 107, vafmd.rep
    assert vafmd.client.hello()["status"] == "ok"
"""
    run(pytester, src % "ipc:///tmp/vafm-", "--basetemp", str(deep)).assert_outcomes(passed=1)
    run(pytester, src % "tcp://127.0.0.1:", "--vafm-transport", "tcp").assert_outcomes(passed=1)


def test_scene_units(pytester):
    r = run(pytester, """
import pytest
def test_units(vafmd, vafm_scene):
    assert vafm_scene("contact-silica", setpoint="1nN", T="300K", v_approach="2um/s") == \\
        {"setpoint_N": 1e-9, "T_K": 300.0, "v_approach_m_per_s": 2e-6}
    got = vafmd.client.get("setpoint_N", "T_K", "v_approach_m_per_s")
    assert got == {"setpoint_N": 1e-9, "T_K": 300.0, "v_approach_m_per_s": 2e-6}
    with pytest.raises(ValueError, match="unit must be N"):
        vafm_scene(setpoint_N="1nm")
    with pytest.raises(ValueError, match="no such parameter"):
        vafm_scene(stiffness=1)
""")
    r.assert_outcomes(passed=1)


def test_one_changed_bit_is_caught(pytester):
    r = run(pytester, """
import numpy as np, pytest
def test_bits(vafmd, vafm_stream):
    run = vafm_stream.run(vafmd.client.curve(index=0)["run_id"])
    saved = {"index": 0, "force_N": run["force_N"].copy(), "height_m": run["height_m"]}
    vafmd.assert_curves_match_log([saved])
    saved["force_N"].view("<u8")[100] ^= np.uint64(1)
    with pytest.raises(AssertionError, match=r"force_N\\[100\\].*not bit for bit"):
        vafmd.assert_curves_match_log([saved])
    saved["force_N"] = saved["force_N"][:-50]
    with pytest.raises(AssertionError, match="samples lost or added"):
        vafmd.assert_curves_match_log([saved])
""")
    r.assert_outcomes(passed=1)


def test_an_unnoticed_fault_is_caught(pytester):
    r = run(pytester, """
import pytest
def test_faults(vafmd, vafm_faults, vafm_stream):
    vafm_faults(script=[{"kind": "drop", "run": 1, "block": 3}])
    run = vafm_stream.run(vafmd.client.curve(index=0)["run_id"], strict=False)
    assert run.gaps == 1
    with pytest.raises(AssertionError, match="fault 1 drop .run 1, block 3.: no 'gap' report"):
        vafmd.assert_faults_noticed([])
    vafmd.assert_faults_noticed(vafm_stream.reports)
    with pytest.raises(AssertionError, match="silently dropped"):
        vafmd.assert_nothing_dropped([])
    vafmd.assert_nothing_dropped([], reported=[1])
""")
    r.assert_outcomes(passed=1)


def test_paced_and_logs_kept_or_removed(pytester):
    src = """
import os, time
def test_paced(vafmd, vafm_stream):
    assert vafmd.client.get("free_run", "speed") == {"free_run": %s, "speed": %s}
    t = time.monotonic()
    vafm_stream.run(vafmd.client.curve(index=0)["run_id"])
    print("WALL", time.monotonic() - t, "FOLDER", vafmd.folder)
"""
    r = run(pytester, src % ("False", "2.0"), "-s", "--vafm-speed", "2")
    r.assert_outcomes(passed=1)
    wall, folder = re.search(r"WALL (\S+) FOLDER (\S+)", r.stdout.str()).groups()
    assert float(wall) >= 0.3004 / 2 * 0.95   # contact-silica's curve: 0.3004 s of samples at 2x real time
    assert not [f for f in os.listdir(folder) if f.startswith("vafmd")]   # a passing test: logs removed
    r = run(pytester, src % ("True", "1.0"), "-s", "--vafm-keep-logs")
    r.assert_outcomes(passed=1)
    wall, folder = re.search(r"WALL (\S+) FOLDER (\S+)", r.stdout.str()).groups()
    assert {"vafmd-1.h5", "vafmd.stderr"} <= set(os.listdir(folder))


def test_engaged_fixture(pytester):
    """vafm_engaged: the controller engaged at the marker's setpoint, its live stream flowing (the Stream's
    live=True must subscribe to "live" by name: the daemon sends it to no one else), the pacing restored; an
    approach that cannot succeed fails the test with its reason."""
    r = run(pytester, """
import numpy as np
import pytest

@pytest.mark.vafm_engage(setpoint="1nN")
def test_engaged(vafm_engaged, vafmd):
    st = vafm_engaged.ctrl()
    assert st["state"] == "engaged" and st["feedback"] and st["in_contact"], st
    assert st["setpoint"]["value"] == 1e-9 and vafm_engaged.event["kind"] == "engaged"
    assert vafmd.client.get("speed")["speed"] == 1.0                # the approach's pacing is undone
    live = vafm_engaged.live(50)
    assert len(live["force_N"]) == 50 and np.all(live["state"] == 2)
    print("FORCE", live["force_N"].mean(), st["setpoint_N"])       # setpoint_N: from the free baseline
    assert abs(live["force_N"].mean() - st["setpoint_N"]) < 0.05e-9
    vafmd.client.set({"T_K": 310.0})                                # rebuilt: the state carries over
    st = vafm_engaged.ctrl()
    assert st["generation"] > vafm_engaged.generation and st["state"] == "engaged", st
    for _ in range(200):                                            # past the points buffered before the set
        after = vafm_engaged.live(10, timeout=10)
        if after["time_s"][-1] > st["time_s"]:
            break
    assert after["time_s"][-1] > st["time_s"] and np.all(after["state"] == 2)

@pytest.mark.vafm_engage(settings={"engage_timeout_s": "2s"})
def test_timeout(vafm_engaged):
    pass
""", "-s")
    r.assert_outcomes(passed=1, errors=1)                            # a fixture that fails: a setup error
    out = r.stdout.str()
    assert "vafm_engaged: engage failed" in out and "'reason': 'timeout'" in out, out


def test_nanonis_fixture(pytester):
    """vafm_nanonis: the daemon also serves the Nanonis port on a free loopback port; one Signals.ValGet
    framed from the vendor's spec (40-byte big-endian headers, the error part ending the response body)."""
    r = run(pytester, """
import socket, struct

def test_valget(vafm_nanonis, vafmd):
    host, port = vafm_nanonis
    assert host == "127.0.0.1" and vafmd.nanonis_port == port and vafmd.client.status()["state"] == "idle"
    with socket.create_connection((host, port), timeout=10) as s:
        s.sendall(struct.pack(">32sih2x", b"Signals.ValGet", 8, 1) + struct.pack(">iI", 0, 0))
        hdr = b""
        while len(hdr) < 40:
            hdr += s.recv(40 - len(hdr))
        name, size = struct.unpack(">32si4x", hdr)
        body = b""
        while len(body) < size:
            body += s.recv(size - len(body))
    assert name.rstrip(b"\\0") == b"Signals.ValGet" and size == 12, (name, size)
    value, status, desc_len = struct.unpack(">fIi", body)
    assert status == 0 and desc_len == 0 and value == value
    print("VALGET", value)

def test_no_port(vafmd):
    assert vafmd.nanonis_port is None
""", "-s")
    r.assert_outcomes(passed=2)
    assert "VALGET" in r.stdout.str()
