"""C for one large SX Function as a chain of small stage functions (the elastic kernel's C).

CasADi writes an SX Function as one C function: one statement per operation, every value a
local. For the kernel of a 7-joint arm (4.4k operations) gcc then keeps about 400 values on a
stack frame of 3 kB, and each access to it takes a 32-bit displacement (9 bytes of code). The
compiled time of that code follows its size, not its operation count: 17.5 ns per kB on the
bench machine for every build measured (-O2, -Os, -mavx, -march=native; 36 to 72 kB), i.e. the
front end fetching 16 bytes a cycle.

Here the same operations, in CasADi's order, are cut into stages of about ``STAGE_OPERATIONS``
operations, each its own ``static`` function kept out of line (``FJM_NOINLINE``; inlined back,
they were one large function again and slower). Each cut is placed where the fewest values cross
it. A stage's frame is small, so its spills take 8-bit displacements; a value that a later stage
reads is stored once in the array ``t`` (on the entry's stack; a slot is reused once its last
reader has run: 402 doubles for the Panda, 1589 for a 21-joint chain) and read from there. Every
operation is the same IEEE operation on the same operands as in CasADi's code, so the results are
bitwise identical; only where values are kept differs.

Measured when this was written (the Panda's ``control_core``, gcc -O2, interleaved runs): 1.04 ->
0.885 us; Baxter 2.71 -> 2.40 us; planar3 0.145 -> 0.136 us; elbow3 unchanged; planar7 0.606 ->
0.635 us in that harness (its bench ratio did not move). Built with ``-march=native`` the Panda's
core was slower staged (0.75 -> 0.79 us): three-operand AVX code spills less, so the stages save
less than they cost. ``make bench`` measures the shipped code.

The entry keeps CasADi's calling convention, ``static int f(const casadi_real** arg,
casadi_real** res, casadi_int* iw, casadi_real* w, int mem)``: an absent input (null) reads as
zeros and an absent output (null) is written to scratch, as in CasADi's own code.
:func:`replace_function` puts it in place of CasADi's definition in a generated file, where
:func:`staged_writer` says stages are worth it.
"""

from __future__ import annotations

import heapq
import math
import re
from functools import partial
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import casadi as ca

__all__ = ["STAGE_OPERATIONS", "staged_c", "staged_writer", "replace_function"]

#: Operations per stage. Measured from 50 to 250 on five models: the Panda was fastest at 80 to 100, Baxter,
#: elbow3, planar3 and planar7 at 100 to 150.
STAGE_OPERATIONS = 100

_FREE = (ca.OP_CONST, ca.OP_INPUT)
# one operation a statement, so no outer parentheses (negative literals have their own, :func:`_literal`)
# (CasADi's C writes the same expressions; what it writes through a helper of its own, such as
# casadi_fmin or casadi_log1p, is not here, and a Function using it keeps CasADi's code)
_BINARY = {ca.OP_ADD: "{0}+{1}", ca.OP_SUB: "{0}-{1}", ca.OP_MUL: "{0}*{1}", ca.OP_DIV: "{0}/{1}",
           ca.OP_POW: "pow({0},{1})", ca.OP_CONSTPOW: "pow({0},{1})", ca.OP_ATAN2: "atan2({0},{1})"}
_UNARY = {ca.OP_NEG: "-{0}", ca.OP_SQ: "{0}*{0}", ca.OP_TWICE: "2.*{0}", ca.OP_INV: "1./{0}",
          ca.OP_SIN: "sin({0})", ca.OP_COS: "cos({0})", ca.OP_TAN: "tan({0})", ca.OP_SQRT: "sqrt({0})",
          ca.OP_EXP: "exp({0})", ca.OP_LOG: "log({0})", ca.OP_FABS: "fabs({0})", ca.OP_TANH: "tanh({0})",
          ca.OP_ASIN: "asin({0})", ca.OP_ACOS: "acos({0})", ca.OP_ATAN: "atan({0})", ca.OP_SINH: "sinh({0})",
          ca.OP_COSH: "cosh({0})"}
_NOINLINE = """#ifndef FJM_NOINLINE  /* the stages below must stay separate functions (derive/emit/staged_c.py) */
#if defined(__GNUC__) || defined(__clang__)
#define FJM_NOINLINE __attribute__((noinline))
#elif defined(_MSC_VER)
#define FJM_NOINLINE __declspec(noinline)
#else
#define FJM_NOINLINE
#endif
#endif
"""


def _op_name(op: int) -> str:
    return next((n for n in dir(ca) if n.startswith("OP_") and getattr(ca, n) == op), str(op))


def _algorithm(fn: ca.Function) -> List[Tuple[int, List[int], List[int], float]]:
    """``(op, deps, out, constant)`` per instruction; ``deps`` are instruction indices (CasADi's
    work slots are reused, so each read is resolved to the slot's latest writer)."""
    writer: Dict[int, int] = {}
    alg = []
    for k in range(fn.n_instructions()):
        op, i, o = fn.instruction_id(k), list(fn.instruction_input(k)), list(fn.instruction_output(k))
        if op in _FREE:
            deps = [] if op == ca.OP_CONST else i  # an input: (argument, nonzero)
        elif op == ca.OP_OUTPUT:
            deps = [writer[i[0]]]
        elif op in _BINARY:
            deps = [writer[i[0]], writer[i[1]]]
        elif op in _UNARY:
            deps = [writer[i[0]]]
        else:
            raise NotImplementedError(f"{fn.name()}: operation {_op_name(op)} has no C form in staged_c; "
                                      f"expected one of {sorted(_op_name(o) for o in (*_BINARY, *_UNARY))}")
        const = fn.instruction_constant(k) if op == ca.OP_CONST else 0.0
        if op == ca.OP_CONST and not math.isfinite(const):
            raise ValueError(f"{fn.name()}: constant {const} is not finite")
        alg.append((op, deps, o, const))
        if op != ca.OP_OUTPUT:
            writer[o[0]] = k
    return alg


def _stages(alg, stage_ops: int) -> Tuple[Dict[int, int], int]:
    """Stage of each computed instruction and output: consecutive runs of ``stage_ops / 2`` to
    ``3 stage_ops / 2`` of them, each cut where the fewest values cross it (they go through ``t``)."""
    seq = [k for k, (op, _, _, _) in enumerate(alg) if op not in _FREE]
    pos = {k: i for i, k in enumerate(seq)}
    crossing = [0] * (len(seq) + 1)  # crossing[i]: values made at or before i and read after i
    last_read: Dict[int, int] = {}
    for k in seq:
        for p in alg[k][1]:
            if p in pos:
                last_read[p] = pos[k]
    for p, r in last_read.items():
        crossing[pos[p]] += 1
        crossing[r] -= 1
    for i in range(1, len(seq)):
        crossing[i] += crossing[i - 1]
    stage, start, s = {}, 0, 0
    while start < len(seq):
        lo, hi = start + stage_ops // 2, start + (3 * stage_ops) // 2
        if hi >= len(seq):
            end = len(seq)
        else:  # cut after the position in [lo, hi) with the fewest crossing values, the nearest the target on ties
            end = 1 + min(range(lo, hi), key=lambda i: (crossing[i], abs(i - start - stage_ops)))
        for k in seq[start:end]:
            stage[k] = s
        start, s = end, s + 1
    return stage, max(s, 1)


def _slots(alg, stage: Dict[int, int]) -> Tuple[Dict[int, int], int]:
    """A slot of ``t`` for each value read in a later stage than its own; a slot is reused by a value of
    a stage after its last reader's. Returns the slots and their number."""
    last: Dict[int, int] = {}  # value -> the last stage that reads it, where that is not its own
    for k, (op, deps, _, _) in enumerate(alg):
        if op in _FREE:
            continue
        for p in deps:
            if p in stage and stage[p] != stage[k]:
                last[p] = max(last.get(p, -1), stage[k])
    slot: Dict[int, int] = {}
    free: List[int] = []  # a heap: the lowest free slot first
    busy: List[Tuple[int, int]] = []  # (last reader's stage, slot)
    size = 0
    for k in sorted(last, key=lambda k: (stage[k], k)):
        for s in [s for e, s in busy if e < stage[k]]:
            heapq.heappush(free, s)
        busy = [(e, s) for e, s in busy if e >= stage[k]]
        if free:
            slot[k] = heapq.heappop(free)
        else:
            slot[k], size = size, size + 1
        busy.append((last[k], slot[k]))
    return slot, size


def _literal(c: float) -> str:
    text = repr(float(c))
    return f"({text})" if c < 0 or text.startswith("-") else text


def _stage_body(alg, ks: Sequence[int], slot: Dict[int, int]) -> List[str]:
    """The statements of one stage, its locals declared first (one per value: gcc allocated registers
    worse when a local was reused, and the Panda's stages were 4 % slower). Not indented: a stage is a
    flat list of assignments, and the 21-joint chain's C would be 50 kB larger."""
    local: Dict[int, str] = {}
    lines = []
    read_here = {p for k in ks if alg[k][0] != ca.OP_INPUT for p in alg[k][1]}

    def ref(p: int) -> str:
        op, deps, _, const = alg[p]
        if op == ca.OP_CONST:
            return _literal(const)
        if op == ca.OP_INPUT:
            return f"x[{deps[0]}][{deps[1]}]"
        return local[p] if p in local else f"t[{slot[p]}]"

    for k in ks:
        op, deps, out, _ = alg[k]
        if op == ca.OP_OUTPUT:
            lines.append(f"y[{out[0]}][{out[1]}]={ref(deps[0])};")
            continue
        expr = (_BINARY.get(op) or _UNARY[op]).format(*map(ref, deps))
        if k not in read_here:  # read only by later stages
            lines.append(f"t[{slot[k]}]={expr};")
            continue
        local[k] = f"a{len(local)}"
        store = f"t[{slot[k]}]=" if k in slot else ""  # read by a later stage too
        lines.append(f"{local[k]}={store}{expr};")
    if local:
        lines.insert(0, "casadi_real " + ",".join(local.values()) + ";")
    return lines


def _plan(fn: ca.Function, stage_ops: int):
    """``(algorithm, stage of each instruction, number of stages)`` of ``fn``."""
    if not fn.is_a("SXFunction"):
        raise TypeError(f"{fn.name()}: staged_c takes an SX Function, got {fn.class_name()}")
    alg = _algorithm(fn)
    return (alg, *_stages(alg, stage_ops))


def staged_c(fn: ca.Function, c_name: str, stage_ops: int = STAGE_OPERATIONS) -> str:
    """C of ``fn`` (an SX Function) as ``static int c_name(arg, res, iw, w, mem)`` and its stages.

    Parameters
    ----------
    fn : casadi.Function
        An SX Function with dense inputs and outputs.
    c_name : str
        Name of the entry function (CasADi's name for ``fn`` in the file it replaces it in).
    stage_ops : int
        Operations per stage.

    Returns
    -------
    str
        The definitions: the ``FJM_NOINLINE`` macro, the stages, then the entry.
    """
    return _write(fn, c_name, *_plan(fn, stage_ops))


def staged_writer(fn: ca.Function, stage_ops: int = STAGE_OPERATIONS) -> Optional[Callable[[str], str]]:
    """``c_name -> staged_c(fn, c_name)``, planned once; None where CasADi's code should stay: ``fn`` has
    one stage's operations (one stage is CasADi's function plus a call), or an operation with no C form here."""
    try:
        alg, stage, n_stages = _plan(fn, stage_ops)
    except NotImplementedError:
        return None
    return None if n_stages <= 1 else partial(_write, fn, alg=alg, stage=stage, n_stages=n_stages)


def _write(fn: ca.Function, c_name: str, alg, stage: Dict[int, int], n_stages: int) -> str:
    """:func:`staged_c` of a planned ``fn``."""
    # names through CasADi's CASADI_PREFIX (the model's name), like CasADi's own: two generated files
    # may then share one translation unit
    base = c_name[len("casadi_"):] if c_name.startswith("casadi_") else c_name

    def local(what) -> str:
        return f"CASADI_PREFIX({base}_{what})"

    slot, n_slots = _slots(alg, stage)
    text = [_NOINLINE]
    members: List[List[int]] = [[] for _ in range(n_stages)]
    for k in stage:  # in program order
        members[stage[k]].append(k)
    for s, ks in enumerate(members):
        body = "\n".join(_stage_body(alg, ks, slot))
        unused = "".join(f"(void){v};" for v in "xyt" if f"{v}[" not in body)
        text.append(f"static FJM_NOINLINE void {local(s)}(const casadi_real* const* x, casadi_real* const* y, "
                    f"casadi_real* t) {{\n" + (f"{unused}\n" if unused else "") + body + "\n}\n\n")
    n_in, n_out = fn.n_in(), fn.n_out()
    zeros = max([fn.nnz_in(i) for i in range(n_in)] + [1])
    text.append(f"static const casadi_real {local('zeros')}[{zeros}] = {{0}};\n\n")
    # (iw, w and mem are unused, like in CasADi's own functions: the writer's _silence_unused says so for both)
    text.append(f"static int {c_name}(const casadi_real** arg, casadi_real** res, casadi_int* iw, "
                f"casadi_real* w, int mem) {{\n")
    scratch = ", ".join(f"y{i}[{max(fn.nnz_out(i), 1)}]" for i in range(n_out))
    text.append(f"  casadi_real t[{max(n_slots, 1)}], {scratch};  /* values between stages; outputs nobody asked for */\n")
    text.append(f"  const casadi_real* x[{max(n_in, 1)}];\n  casadi_real* y[{max(n_out, 1)}];\n")
    text += [f"  x[{i}] = arg[{i}] ? arg[{i}] : {local('zeros')};\n" for i in range(n_in)]
    text += [f"  y[{i}] = res[{i}] ? res[{i}] : y{i};\n" for i in range(n_out)]
    text += [f"  {local(s)}(x, y, t);\n" for s in range(n_stages)]
    text.append("  return 0;\n}\n")
    return "".join(text)


def replace_function(src: str, fn_name: str, definition_of) -> str:
    """``src`` (a CasADi-generated C file) with the definition of the Function ``fn_name`` replaced.

    CasADi writes ``/* <fn_name>:(...)->(...) */`` above ``static int casadi_fN(...) {``, and the
    body ends at the next line that is ``}``. ``definition_of(c_name)`` returns the new definition.
    """
    head = re.search(rf"^/\* {re.escape(fn_name)}:\(.*\*/\n(static int (casadi_f\d+)\(.*\{{)$", src, re.M)
    if head is None:
        raise ValueError(f"no definition of {fn_name} in the generated C")
    start = head.start(1)
    end = src.index("\n}\n", start) + 3
    return src[:start] + definition_of(head.group(2)) + src[end:]
