# SPDX-License-Identifier: MIT
"""Tests of acquire.py against a vafmd, with nothing but the vafm_client pytest plugin: each test gets a
fresh daemon (free run, private ipc:// endpoints), its HDF5 log as the ground truth, and a fault plan when
it asks for one. Run: pytest --vafmd build/src/daemon/vafmd clients/python/examples/pytest_acquisition
(with the plugin installed, or add -p vafm_client.pytest_plugin)."""
import pytest

import acquire

N = 4  # curves per test


def test_curves_saved_equal_the_instrument(vafmd, vafm_scene, tmp_path):
    vafm_scene("contact-silica", setpoint="1nN")
    saved, reports = acquire.take_curves(vafmd.rep, vafmd.pub, N, tmp_path / "curves")
    assert len(saved) == N and not reports
    curves = acquire.load_curves(tmp_path / "curves")
    vafmd.assert_curves_match_log(curves)          # bit for bit, also the number of samples
    vafmd.assert_nothing_dropped(saved)
    truth = {int(c.truth["curve"]): c.truth["touch_height_m"] for c in vafmd.log()}
    for c in curves:  # the contact point within 1 nm of the height where the tip touched
        assert abs(acquire.contact_point(c) - truth[c["index"]]) < 1e-9


def test_pulloff_within_its_error(vafmd, vafm_scene, tmp_path):
    # detector noise of 2 mV rms (12 pN of force): each pull-off within k = 3 of its standard errors of the
    # daemon's noise-free one, over N = 4 seeded curves (deviations measured: 0.2 to 1.2 standard errors)
    vafm_scene(noise_V_rms="2mV")
    acquire.take_curves(vafmd.rep, vafmd.pub, N, tmp_path / "curves")
    curves = acquire.load_curves(tmp_path / "curves")
    vafmd.assert_pulloffs({c["index"]: acquire.pulloff(c) for c in curves}, k=3)


def test_faults_are_noticed_and_nothing_is_dropped(vafmd, vafm_faults, tmp_path):
    # about 1 block of the 240 of 4 curves: a seeded plan, so the same faults strike every time
    plan = vafm_faults(drop=0.005, seed=3)
    saved, reports = acquire.take_curves(vafmd.rep, vafmd.pub, N, tmp_path / "curves")
    records = vafmd.assert_faults_noticed(reports)
    assert any(r["kind"] == "drop" for r in records) and records == plan.records()
    lost = [r["run_id"] for r in reports if r["kind"] == "lost"]
    vafmd.assert_nothing_dropped(saved, reported=lost)
    vafmd.assert_curves_match_log(acquire.load_curves(tmp_path / "curves"))


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="on purpose: careless acquisition saves a run with a sequence gap; the plugin "
                          "must catch it (an unexpected pass fails the run)")
def test_a_careless_module_is_caught(vafmd, vafm_faults, tmp_path):
    vafm_faults(script=[{"kind": "drop", "run": 2, "block": 10, "blocks": 3}])
    saved, reports = acquire.take_curves(vafmd.rep, vafmd.pub, N, tmp_path / "curves", careless=True)
    vafmd.assert_nothing_dropped(saved, reported=[r["run_id"] for r in reports if r["kind"] == "lost"])
