# SPDX-License-Identifier: MIT
"""One list of daemon commands (issue #25): src/daemon/commands.def declares them; everything that lists
them again must say the same. Checked against the table: protocol/commands.schema.json (names and each
command's keys), wire.md §2.3's command table (names, arguments, resend, run), `vafmd --help`, `vafm ctl
--help`, hello's capabilities (as a set: their order is 0.5's), the decoder's keys and "known:" list, the
fault plan's command names (every faultable command is accepted, the others refused), and the Python
client's idempotent set. Also one table per fact for the
defaults: wire.md's settings and detector tables and `vafmd --help`'s --sensitivity say what `get`
returns (0.6.2's said 50e-9; the default preset has 6e-8).

Needs $VAFMD and $VAFM_CLI (a missing one is a failure, not a skip)."""
import json
import math
import os
import re
import subprocess
import sys

import pytest

from vafmd_harness import ROOT, VAFM_CLI, VAFMD, Daemon, read, reap_daemons  # noqa: F401

sys.path.insert(0, os.path.join(ROOT, "clients", "python"))


def table():
    """[(name, keys, flags)] of commands.def, in order."""
    text = re.sub(r"/\*.*?\*/", "", read("src", "daemon", "commands.def"), flags=re.S)
    rows = re.findall(r'VAFMD_COMMAND\(\s*(\w+)\s*,\s*"(\w+)"\s*,\s*"([^"]*)"\s*,\s*([^,]*?)\s*,\s*(\w+)\s*,'
                      r'\s*"([^"]*)"\s*\)', text)
    assert len(rows) == text.count("VAFMD_COMMAND("), "a row of commands.def does not parse"
    out = []
    for ident, name, keys, flags, _handler, _help in rows:
        assert ident == name.upper(), (ident, name)
        fl = set() if flags.strip() == "0" else {f.strip().replace("VAFMD_CF_", "") for f in flags.split("|")}
        assert fl <= {"IDEMPOTENT", "FAULTABLE", "STARTS_RUN", "READ_ONLY"}, fl
        out.append((name, keys.split(), fl))
    assert len(out) >= 14 and len({r[0] for r in out}) == len(out)
    return out


NAMES = [r[0] for r in table()]


def test_environment():
    assert VAFMD and os.access(VAFMD, os.X_OK), "set VAFMD to the vafmd executable"
    assert VAFM_CLI and os.access(VAFM_CLI, os.X_OK), "set VAFM_CLI to the vafm executable"


def test_schema():
    s = json.loads(read("protocol", "commands.schema.json"))
    assert s["properties"]["cmd"]["enum"] == NAMES
    keys = {}
    for branch in s["oneOf"]:
        props = branch["properties"]
        cmd = props["cmd"]
        names = [cmd["const"]] if "const" in cmd else cmd["enum"]
        assert branch.get("additionalProperties") is False, names
        for n in names:
            assert n not in keys, f"{n}: two branches"
            keys[n] = sorted(set(props) - {"cmd", "id"})
    assert keys == {n: sorted(k) for n, k, _ in table()}


def wire_command_table():
    text = read("protocol", "wire.md")
    head = "| command | arguments besides `cmd`, `id` | resend | run | what it does |"
    assert head in text
    rows = []
    for line in text.split(head, 1)[1].splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows.append((cells[0].strip("`"), re.findall(r"`(\w+)`", cells[1]), cells[2] == "yes", cells[3] == "yes"))
    return rows


def test_wire_md_table():
    assert wire_command_table() == [(n, k, "IDEMPOTENT" in f, "STARTS_RUN" in f) for n, k, f in table()]


def test_wire_md_sections():
    """Each command has its own section (#### `name`) in §2.3."""
    text = read("protocol", "wire.md")
    for n in NAMES:
        assert f"#### `{n}`" in text, n


def test_vafmd_help():
    out = subprocess.run([VAFMD, "--help"], capture_output=True, text=True, check=True).stdout
    sec = out.split("\nCOMMANDS", 1)[1].split("\n\n", 1)[0].splitlines()[1:]
    assert [line.split()[0] for line in sec] == NAMES
    assert all(len(line.split(None, 1)) == 2 for line in sec), "a command without help"


def help_settings(out):
    """[name] of `vafmd --help`'s PARAMETERS AND SETTINGS section, one per line, in order."""
    assert "\nPARAMETERS AND SETTINGS" in out, "vafmd --help lists no parameters and settings"
    sec = out.split("\nPARAMETERS AND SETTINGS", 1)[1].split("\n\n", 1)[0].splitlines()[1:]
    return [line.split()[0] for line in sec if line.startswith("  ") and not line.startswith("   ")]


def test_vafmd_help_lists_every_setting():
    """Every key `get` accepts (scene parameters, daemon settings, ctrl_*, monitor_rate_Hz, ctrl_sample; issue
    #26: 0.7.0's help named 16 of them) is in `vafmd --help`, once, with a description, and nothing else is."""
    out = subprocess.run([VAFMD, "--help"], capture_output=True, text=True, check=True).stdout
    names = help_settings(out)
    d = Daemon()
    keys = set(d.cmd({"cmd": "get"})["values"])
    d.stop()
    assert {"monitor_rate_Hz", "ctrl_sample", "ctrl_setpoint", "segment_channel", "k_N_per_m"} <= keys
    assert sorted(set(names)) == sorted(names), "a name listed twice"
    assert keys - set(names) == set(), f"get's keys missing from vafmd --help: {sorted(keys - set(names))}"
    assert set(names) - keys == set(), f"vafmd --help lists what get does not know: {sorted(set(names) - keys)}"
    sec = out.split("\nPARAMETERS AND SETTINGS", 1)[1].split("\n\n", 1)[0].splitlines()[1:]
    first = {line.split()[0]: line for line in sec if line.startswith("  ") and not line.startswith("   ")}
    assert all(len(first[n].split()) >= 2 for n in names), "a setting without description"


def test_ctl_help():
    out = subprocess.run([VAFM_CLI, "ctl", "--help"], capture_output=True, text=True, check=True).stdout
    lines = out.splitlines()
    i = next(i for i, line in enumerate(lines) if line.startswith("Commands"))
    assert lines[i + 1].split() == NAMES


def test_python_idempotent_set():
    from vafm_client import client
    assert client._IDEMPOTENT == {n for n, _, f in table() if "IDEMPOTENT" in f}


def test_hello_and_fault_plans():
    d = Daemon()
    caps = d.cmd({"cmd": "hello"})["capabilities"]
    assert sorted(caps) == sorted(NAMES) and len(caps) == len(NAMES), caps  # the order is 0.5's
    for n, _, f in table():
        r = d.cmd({"cmd": "faults", "plan": {"script": [{"kind": "busy", "cmd": n, "nth": 1000}]}})
        if "FAULTABLE" in f:
            assert r["status"] == "ok", (n, r)
        else:
            assert r["status"] == "error" and r["field"] == "script[0].cmd" and "never faulted" in r["message"], r
    r = d.cmd({"cmd": "nope"})
    assert r["code"] == "unknown_command" and r["message"].endswith("(known: " + " ".join(NAMES) + ")"), r
    # each command refuses a key it does not take, naming it
    for n in NAMES:
        r = d.cmd({"cmd": n, "zz_not_a_key": 1})
        assert r["code"] == "unknown_field" and r["field"] == "zz_not_a_key", (n, r)
    d.stop()


def defaults_table(text, head):
    """{name: default text} of the markdown table whose header row starts with head."""
    i = text.index(head)
    lines = text[i:].splitlines()
    cols = [c.strip() for c in lines[0].strip("|").split("|")]
    k = cols.index("default")
    out = {}
    for line in lines[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[cells[0].strip("`")] = cells[k]
    return out


def parse_default(cell):
    tok = cell.replace("`", "").split()[0]
    if tok in ("true", "false"):
        return tok == "true"
    try:
        return float(tok)
    except ValueError:
        return tok


def same(doc, got):
    if isinstance(got, bool) or isinstance(doc, (bool, str)):
        return doc == got
    return math.isclose(doc, got, rel_tol=1e-12, abs_tol=0)


def test_defaults_equal_get():
    text = read("protocol", "wire.md")
    doc = {**defaults_table(text, "| setting | type |"), **defaults_table(text, "| scene parameter | type |")}
    assert {"speed", "free_run", "block_s", "hwm", "kernel", "lookahead_s", "sensitivity_m_per_V",
            "noise_V_rms", "adc_bits", "adc_range_V", "baseline_offset_V"} <= set(doc)
    d = Daemon()
    got = d.cmd({"cmd": "get", "names": sorted(doc)})["values"]
    d.stop()
    wrong = {n: (doc[n], got[n]) for n in doc if not same(parse_default(doc[n]), got[n])}
    assert not wrong, f"wire.md's default (doc, get): {wrong}"
    out = subprocess.run([VAFMD, "--help"], capture_output=True, text=True, check=True).stdout
    m = re.search(r"--sensitivity S .*?default[^0-9]*([0-9.e+-]+)\)", out)
    assert m and same(float(m.group(1)), got["sensitivity_m_per_V"]), (m and m.group(0), got["sensitivity_m_per_V"])


def test_format_version_in_docs():
    """wire.md's log and hdf5.md name the format version the writer writes (0.6.2's said 1.0, files 1.1)."""
    h = read("src", "h5", "h5.h")
    v = "%s.%s" % (re.search(r"#define VAFM_H5_FORMAT_MAJOR (\d+)", h).group(1),
                   re.search(r"#define VAFM_H5_FORMAT_MINOR (\d+)", h).group(1))
    assert f"(afmformats' layout, vafm format {v})" in read("protocol", "wire.md")
    hdf5 = read("protocol", "hdf5.md")
    assert hdf5.splitlines()[0].endswith(f"vafm format version {v})")
    assert f'| `vafm format version` | string | `"{v}"`' in hdf5
