"""Identification against an engine nobody here wrote: MuJoCo logs of the TRUE link1 (examples/identify_roundtrip.py).

The true plant (stiffness x1.15, rotor inertia x0.9, B_m 0.3, MuJoCo's dry ``frictionloss`` 0.4 N m
on the rotor) is exported with ``fjm export mjcf``, driven along a ``fjm excite`` trajectory by a
motor-side PD, and logged with the ``franka_like`` sensor levels (quantized noisy encoders, tau_J
noise and offset). Only the log reaches the identification.
"""
import numpy as np
import pytest

import fjm_runtime
from fjm_runtime.ident.excite import design_excitation
from fjm_runtime.ident.identify import identify
from support.paths import load_example

import mujoco  # noqa: F401 - the dev extra: a missing install must fail, not skip


@pytest.fixture(scope="module")
def rt():
    return load_example("identify_roundtrip")


def _identified(rt, duration, tmp_path, periods=1):
    """link1 identified from a MuJoCo log of ``periods`` times the excitation designed for ``duration`` s."""
    m = fjm_runtime.load("link1")
    exc = design_excitation(m, duration, candidates=10)
    log = rt.mujoco_log(m, exc.reference, periods * exc.duration, tmp_path)
    return m, identify(m, log), rt.true_params(m)


def test_short_mujoco_log_meets_the_tolerances(rt, tmp_path):
    m, ident, true = _identified(rt, 6.0, tmp_path)
    v = ident.values
    print({k: f"{100 * (v[k] / true[k] - 1):+.2f} %" for k in ("K", "J_m", "B_m")},
          f"F_c {100 * (v['F_c1'] / rt.FRICTION - 1):+.2f} %")
    assert abs(v["K"] / true["K"] - 1) <= 0.02
    assert abs(v["J_m"] / true["J_m"] - 1) <= 0.05
    assert abs(v["F_c1"] / rt.FRICTION - 1) <= 0.10


@pytest.mark.exhaustive
def test_longer_mujoco_log_tightens(rt, tmp_path):
    """The same excitation played 4 times as long: the standard errors shrink (ideally by half)."""
    _, short, true = _identified(rt, 6.0, tmp_path)
    _, long, _ = _identified(rt, 6.0, tmp_path, periods=4)
    for k in ("K", "J_m", "F_c1"):
        assert long.stderr[k] < 0.7 * short.stderr[k], (k, short.stderr[k], long.stderr[k])
    assert abs(long.values["K"] / true["K"] - 1) <= abs(short.values["K"] / true["K"] - 1) + 0.002


@pytest.mark.exhaustive
def test_round_trip_link1_holds_on_the_true_mujoco_plant(rt, tmp_path):
    """excite -> MuJoCo log -> identify -> params.toml -> fjm design --params -> the C library on the TRUE
    MuJoCo plant with noise and one sample of delay (a short loop; 16 s with a design and a C build:
    CI's exhaustive pass)."""
    assert rt.main(["link1", "--duration", "6", "--loop-duration", "3", "--out", str(tmp_path)]) == 0
