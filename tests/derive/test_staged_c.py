"""derive.emit.staged_c: an SX Function's C in stages computes exactly what CasADi's C computes.

Each case writes a Function's C as ``make derive`` writes the elastic kernel's (CasADi's code
generator, then the Function's definition replaced by the staged one), compiles it with ``-std=c99 -Wall -Wextra -Werror -pedantic -O2`` and calls it through ctypes. The
outputs must equal CasADi's numbers bit for bit: every operation is the same IEEE operation on the
same operands. Stages of 1 and 2 operations pass nearly every value between stages through ``t``
and reuse its slots as early as allowed, so a slot reused too soon or a value read from the wrong
place changes the numbers.
"""

from __future__ import annotations

import ctypes
import subprocess
from functools import partial
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from support.c_function import CFunction

from derive.emit.staged_c import replace_function, staged_c, staged_writer

pytestmark = pytest.mark.slow  # builds C

STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-fPIC", "-shared"]


def _sample_function() -> ca.Function:
    """Every operation staged_c writes, constants of both signs, an output that is an input and one
    that is a constant, a matrix output."""
    x, y = ca.SX.sym("x", 5), ca.SX.sym("y", 3)
    a = ca.sin(x[0]) * y[1] - ca.cos(x[1] + 0.25) / (2.0 + x[2] ** 2)
    b = ca.sqrt(1.0 + a * a) - (-1.5) * x[3]
    c = [a * b - x[4], -b + 3.0 * y[0], ca.exp(-ca.fabs(a)) + ca.log(2.0 + y[2] ** 2), ca.tan(0.1 * y[1])]
    c = [c[0] + ca.atan2(c[1], 2.0 + c[2] ** 2) * ca.tanh(c[3]), c[1] - ca.asin(0.5 * ca.sin(c[0])),
         c[2] * ca.acos(0.25 * ca.cos(c[1])) + ca.atan(c[3]), ca.sinh(0.1 * c[3]) - ca.cosh(0.1 * c[2]) / 3.0,
         (1.5 + ca.sin(c[0]) ** 2) ** y[1] + (1.0 + c[3] ** 2) ** 1.5]
    c = [c[0] + c[4], c[1], c[2], c[3]]
    for _ in range(6):  # a longer chain, so that values live across many stages
        c = [c[1] * c[2] - c[0], c[2] + 0.5 * c[3], c[3] - c[0] * 0.125, c[0] / (1.0 + c[1] ** 2)]
    f1 = ca.vertcat(*c)
    f2 = ca.reshape(ca.vertcat(a + b, x[0], 7.0, c[0] * y[1]), 2, 2)
    return ca.Function("F", [x, y], [f1, f2], ["x", "y"], ["f1", "f2"])


def _build(fn: ca.Function, stage_ops: int, tmp: Path, monkeypatch) -> CFunction:
    """``fn``'s C as make derive writes it (:func:`derive.emit.writer.generate_c` with ``fn`` staged), in
    stages of ``stage_ops``, compiled strictly."""
    from derive.emit import writer
    monkeypatch.setattr(writer, "staged_writer", partial(staged_writer, stage_ops=stage_ops))
    src = writer.generate_c("f", {fn.name(): fn}, tmp, staged=(fn,))["f.c"]
    assert "FJM_NOINLINE void" in src  # the definition was replaced
    (tmp / "staged.c").write_text(src)
    lib = tmp / f"staged{stage_ops}.so"
    proc = subprocess.run(["gcc", *STRICT, str(tmp / "staged.c"), "-o", str(lib), "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[:3000]
    return CFunction(ctypes.CDLL(str(lib)), fn.name(), ctypes.c_double)


def _call(c: CFunction, inputs, skip_out=()):
    """The outputs' nonzeros (dense, column by column), as :func:`_expected` gives them."""
    return [o.ravel(order="F") for o in c(*inputs, skip_out=skip_out)]


def _expected(fn: ca.Function, inputs):
    return [np.asarray(v, float).ravel(order="F") for v in fn.call([ca.DM(v) for v in inputs])]


@pytest.mark.parametrize("stage_ops", [1, 2, 7, 40])
def test_staged_c_equals_casadi_bitwise(stage_ops, tmp_path, monkeypatch):
    fn = _sample_function()
    c = _build(fn, stage_ops, tmp_path, monkeypatch)
    rng = np.random.default_rng(stage_ops)
    for _ in range(5):
        inputs = [rng.uniform(-2, 2, 5), rng.uniform(-2, 2, 3)]
        for got, want in zip(_call(c, inputs), _expected(fn, inputs)):
            np.testing.assert_array_equal(got, want)


def test_absent_inputs_read_as_zeros_and_absent_outputs_are_skipped(tmp_path, monkeypatch):
    fn = _sample_function()
    c = _build(fn, 3, tmp_path, monkeypatch)
    x = np.linspace(-1, 1, 5)
    got = _call(c, [x, None])
    for g, w in zip(got, _expected(fn, [x, np.zeros(3)])):
        np.testing.assert_array_equal(g, w)
    got = _call(c, [x, np.ones(3)], skip_out=(0,))
    assert np.all(np.isnan(got[0]))  # not written
    np.testing.assert_array_equal(got[1], _expected(fn, [x, np.ones(3)])[1])


def test_a_model_kernel_staged_equals_casadi(tmp_path, monkeypatch):
    """The elbow3 elastic kernel (the Function make derive stages), in stages of 5 operations."""
    from derive.emit.dynamics import build_kernel, elastic_kernel
    from derive.registry import build
    m = build("elbow3")
    kernel = elastic_kernel(m, build_kernel(m))
    c = _build(kernel, 5, tmp_path, monkeypatch)
    rng = np.random.default_rng(3)
    p = np.array([pp.default for pp in m.params])
    for _ in range(3):
        inputs = [rng.uniform(-1, 1, m.n) for _ in range(5)] + [p]
        for got, want in zip(_call(c, inputs), _expected(kernel, inputs)):
            np.testing.assert_array_equal(got, want)


def test_errors_name_what_is_wrong():
    x = ca.SX.sym("x")
    with pytest.raises(NotImplementedError, match="OP_FMIN"):
        staged_c(ca.Function("g", [x], [ca.fmin(x, 2.0 + x)]), "casadi_f0")
    with pytest.raises(TypeError, match="SX Function"):
        xm = ca.MX.sym("x")
        staged_c(ca.Function("h", [xm], [2 * xm]), "casadi_f0")
    with pytest.raises(ValueError, match="no definition of K"):
        replace_function("/* F:(x)->(y) */\nstatic int casadi_f0(const casadi_real** arg) {\n}\n", "K", str)


def test_a_function_of_one_stage_keeps_casadis_code(tmp_path):
    """One stage would be CasADi's function plus a call: make derive leaves such a kernel as it is."""
    from derive.emit.writer import generate_c
    fn = _sample_function()
    n_ops = sum(fn.instruction_id(k) not in (ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT) for k in range(fn.n_instructions()))
    assert staged_writer(fn, stage_ops=n_ops // 3) is not None and staged_writer(fn, stage_ops=n_ops) is None
    assert "FJM_NOINLINE" not in generate_c("f", {"F": fn}, tmp_path, staged=(fn,))["f.c"]  # n_ops < 1.5 x 100


def test_a_function_with_an_operation_staged_c_cannot_write_keeps_casadis_code(tmp_path):
    """``fmin`` (CasADi writes it through a helper of its own): make derive keeps CasADi's code, no error."""
    from derive.emit.writer import generate_c
    x = ca.SX.sym("x", 4)
    e = x
    for _ in range(80):
        e = ca.sin(e) * 1.01 + ca.cos(e[::-1])
    fn = ca.Function("G", [x], [ca.fmin(e, 0.5)])
    assert staged_writer(fn, stage_ops=10) is None
    assert "FJM_NOINLINE" not in generate_c("g", {"G": fn}, tmp_path, staged=(fn,))["g.c"]
