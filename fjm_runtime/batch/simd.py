"""SIMD across runs: the batch sample step (:mod:`fjm_runtime.batch.sampled`) emitted "structure of arrays".

Every scalar instruction of the SX Function becomes one statement on a vector of
``LANES`` runs (GCC vector extensions), which the compiler turns into AVX-512, AVX2
or SSE2 instructions; sin/cos go to glibc's vector math library (libmvec);
instructions that depend on the per-run parameters only are evaluated once per run.
Results agree with the scalar code to rounding (libmvec sin/cos: < 4 ulp;
``x / p -> x * (1 / p)``), not bit for bit. The fixed C text is the template
``simd_template.c`` next to this module; :func:`soa_source` fills in the statements.
"""
from __future__ import annotations

import math

from importlib import resources
from string import Template
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import casadi as ca
import numpy as np

from ..ccache import DEFAULT_FLAGS, CompileError, compile_library
from .scalar import SampledBatchRunner, noise_source

#: Largest step (SX instructions) emitted in SIMD form (a guard against pathological
#: compile times; gcc handles the vector-extension code in about linear time:
#: link1 0.2 s, planar3 0.3 s). Baxter's design step (15 joints, per-joint gains as inputs,
#: delay prediction) has about 240k.
SIMD_MAX_INSTRUCTIONS = 400000

#: C expression of each unary SX operation on vectors (``{a}``: the operand).
UNARY = {
    ca.OP_NEG: "-({a})", ca.OP_SQ: "({a})*({a})", ca.OP_TWICE: "2.*({a})", ca.OP_INV: "1./({a})",
    ca.OP_SIN: "v_sin({a})", ca.OP_COS: "v_cos({a})", ca.OP_TAN: "v_tan({a})", ca.OP_EXP: "v_exp({a})",
    ca.OP_LOG: "v_log({a})", ca.OP_SQRT: "v_sqrt({a})", ca.OP_TANH: "v_tanh({a})",
    ca.OP_ATAN: "v_atan({a})", ca.OP_ASIN: "v_asin({a})", ca.OP_ACOS: "v_acos({a})",
    ca.OP_FABS: "(vd)((vl)({a}) & 0x7fffffffffffffffLL)",
    ca.OP_NOT: "v_b(({a}) == 0.)", ca.OP_ASSIGN: "({a})",
    ca.OP_SIGN: "v_sign({a})", ca.OP_FLOOR: "v_floor({a})", ca.OP_CEIL: "v_ceil({a})",
}

#: C expression of each binary SX operation on vectors (``{a}``, ``{b}``: the operands).
BINARY = {
    ca.OP_ADD: "({a})+({b})", ca.OP_SUB: "({a})-({b})", ca.OP_MUL: "({a})*({b})",
    ca.OP_DIV: "({a})/({b})", ca.OP_POW: "v_pow({a},{b})", ca.OP_CONSTPOW: "v_pow({a},{b})",
    ca.OP_FMIN: "v_sel(({a})<({b}), {a}, {b})", ca.OP_FMAX: "v_sel(({a})>({b}), {a}, {b})",
    ca.OP_LT: "v_b(({a})<({b}))", ca.OP_LE: "v_b(({a})<=({b}))",
    ca.OP_EQ: "v_b(({a})==({b}))", ca.OP_NE: "v_b(({a})!=({b}))",
    ca.OP_AND: "v_b((({a})!=0.) & (({b})!=0.))", ca.OP_OR: "v_b((({a})!=0.) | (({b})!=0.))",
    ca.OP_IF_ELSE_ZERO: "(vd)((vl)({b}) & (({a}) != 0.))", ca.OP_ATAN2: "v_atan2({a},{b})",
    ca.OP_COPYSIGN: "v_copysign({a},{b})",
}

#: The vector mask (-1 / 0 per lane) of each comparison, for an ``OP_IF_ELSE_ZERO`` it feeds.
MASKS = {ca.OP_LT: "(({a})<({b}))", ca.OP_LE: "(({a})<=({b}))", ca.OP_EQ: "(({a})==({b}))",
         ca.OP_NE: "(({a})!=({b}))", ca.OP_NOT: "(({a})==0.)"}


class SoaProgram:
    """The statements of one SX Function in SIMD form, split into prologue and step body.

    ``prologue`` lines fill ``inv[j]`` (constants and everything computed from the
    per-run invariant inputs only, once per run group); ``body`` lines compute the
    work vectors ``w<k>`` of one step. ``src[slot]`` says where the value of an SX
    work slot lives: ``("inv", j)`` or ``("w", slot)``.
    """

    def __init__(self, varying: Sequence[int], invariant: Iterable[int] = (), callees: Optional[dict] = None,
                 io: Optional[Tuple[Sequence[int], Sequence[int]]] = None, passthrough: Iterable[int] = ()):
        #: Entries of input 0 constant along a run (loaded once, in the prologue); ``passthrough``: the
        #: entries of output 0 that are input 0's same entry (never stored: both buffers hold them).
        self.varying, self.invariant, self.passthrough = tuple(varying), frozenset(invariant), frozenset(passthrough)
        #: Called Functions emitted so far, shared with nested programs: (name, invariant inputs) -> (C name,
        #: C text, invariant slots), in definition order (a callee's own callees first).
        self.callees: Dict[tuple, Tuple[str, str, int]] = {} if callees is None else callees
        #: For a callee: the offsets of its inputs and outputs in the flat ``in`` / ``out`` vectors.
        self.io = io
        self._sx = None
        self.body: List[str] = []
        self.prologue: List[str] = []
        self.src: Dict[int, Tuple[str, int]] = {}
        self.recip: Dict[int, int] = {}
        self.used: set = set()
        self.n_inv = 0
        #: Work vectors holding a comparison (1.0 / 0.0): slot -> the C variable of its mask.
        self.masks: Dict[int, str] = {}
        #: Prologue blocks of the callees' invariant parts: (callee, invariant argument refs) -> offset in ``inv``.
        self.blocks: Dict[tuple, int] = {}

    def new_inv(self) -> int:
        """A fresh slot of the invariant array ``inv``."""
        self.n_inv += 1
        return self.n_inv - 1

    def ref(self, slot: int) -> str:
        """The C name of the value in SX work slot ``slot``."""
        kind, j = self.src[slot]
        return f"inv[{j}]" if kind == "inv" else f"w{j}"

    def _set_inv(self, slot: int, line_of_j) -> None:
        j = self.new_inv()
        self.prologue.append(line_of_j(j))
        self.src[slot] = ("inv", j)

    def _set_w(self, slot: int, line: str) -> None:
        self.body.append(line)
        self.src[slot] = ("w", slot)
        self.used.add(slot)
        self._wrote(slot)

    def _wrote(self, slot: int) -> None:
        """Forget the comparison held in work vector ``slot``: it was overwritten."""
        self.masks.pop(slot, None)

    def add_input(self, i, o) -> None:
        """``OP_INPUT``: entry ``i[1]`` of input ``i[0]`` into slot ``o[0]``."""
        if self.io is not None and self.io[0][i[0]] + i[1] in self.invariant:
            self._set_inv(o[0], lambda j: f"inv[{j}] = in[{self.io[0][i[0]] + i[1]}];")
        elif self.io is not None:
            self._set_w(o[0], f"w{o[0]} = in[{self.io[0][i[0]] + i[1]}];")
        elif i[0] == 0 and i[1] in self.invariant:
            self._set_inv(o[0], lambda j: f"memcpy(&inv[{j}], acc + {i[1]}*LANES, sizeof(vd));")
        elif i[0] in self.varying:
            self._set_w(o[0], f"memcpy(&w{o[0]}, arg[{i[0]}] + {i[1]}*LANES, sizeof(vd));")
        else:
            self._set_w(o[0], f"w{o[0]} = V0 + arg[{i[0]}][{i[1]}];")

    def add_operation(self, op: int, i, o) -> None:
        """A unary or binary operation: hoisted if its operands are invariant, ``x / inv`` as ``x * (1 / inv)``."""
        args = list(i[:1]) if op in UNARY else list(i[:2])
        fmt = UNARY[op] if op in UNARY else BINARY[op]
        if all(self.src[a][0] == "inv" for a in args):
            expr = fmt.format(a=self.ref(args[0]), b=self.ref(args[-1]))
            self._set_inv(o[0], lambda j: f"inv[{j}] = " + expr + ";")
            return
        if op == ca.OP_DIV and self.src[args[1]][0] == "inv":
            d = self.src[args[1]][1]
            if d not in self.recip:
                self.recip[d] = self.new_inv()
                self.prologue.append(f"inv[{self.recip[d]}] = 1./inv[{d}];")
            expr = f"({self.ref(args[0])})*inv[{self.recip[d]}]"
        elif op == ca.OP_IF_ELSE_ZERO and args[0] in self.masks:   # the comparison's own mask, not 1.0 != 0.
            expr = f"(vd)((vl)({self.ref(args[1])}) & {self.masks[args[0]]})"
        elif op in MASKS:   # the mask kept in a variable of its own (m<k>) for the if_else_zero it may feed
            mask = f"m{len(self.body)}"
            self.body.append(f"vl {mask} = {MASKS[op].format(a=self.ref(args[0]), b=self.ref(args[-1]))};")
            self._set_w(o[0], f"w{o[0]} = v_b({mask});")
            self.masks[o[0]] = mask
            return
        else:
            expr = fmt.format(a=self.ref(args[0]), b=self.ref(args[-1]))
        self._set_w(o[0], f"w{o[0]} = {expr};")

    def add(self, step: ca.Function, k: int) -> None:
        """Instruction ``k`` of ``step``."""
        op = step.instruction_id(k)
        i = step.instruction_input(k)
        o = step.instruction_output(k)
        if op == ca.OP_CONST:
            value = float(step.instruction_constant(k))
            text = repr(value) if math.isfinite(value) else ("NAN" if math.isnan(value) else
                                                              ("INFINITY" if value > 0 else "-INFINITY"))
            self._set_inv(o[0], lambda j: f"inv[{j}] = V0 + {text};")  # C spells inf and nan as macros
        elif op == ca.OP_INPUT:
            self.add_input(i, o)
        elif op == ca.OP_OUTPUT and self.io is not None:
            self.body.append(f"out[{self.io[1][o[0]] + o[1]}] = {self.ref(i[0])};")
        elif op == ca.OP_OUTPUT and o[0] == 0 and o[1] in self.passthrough:
            pass
        elif op == ca.OP_OUTPUT:
            self.body.append(f"{{ vd t = {self.ref(i[0])}; memcpy(res[{o[0]}] + {o[1]}*LANES, &t, sizeof(vd)); }}")
        elif op == ca.OP_CALL:
            self.add_call(step, k, i, o)
        elif op in UNARY or op in BINARY:
            self.add_operation(op, i, o)
        else:
            raise ValueError(f"soa_source: operation {op} not supported")


    def add_call(self, step: ca.Function, k: int, i, o) -> None:
        """``OP_CALL`` (an SX call node of a ``never_inline`` Function): one call of its SIMD form.

        The callee is emitted once per pattern of invariant arguments (:func:`callee_source`: its inputs'
        and outputs' nonzeros flattened). What it computes from its invariant arguments and constants
        only (the parameters' products, the reciprocals of the inertias it divides by) is evaluated by
        its ``_pro`` part in this program's prologue into a block of ``inv`` (one block per distinct
        invariant arguments: the substeps of a sample share it); here its arguments are gathered, it
        is called with that block, and each used output lands in its work slot.
        """
        if self._sx is None:
            self._sx = step.instructions_sx()
        fn = self._sx[k].which_function()
        fixed = [j for j, a in enumerate(i) if self.src[a][0] == "inv"]
        cname, n_inv = callee_source(fn, self.callees, fixed)
        block = (cname,) + tuple(self.ref(i[j]) for j in fixed)
        if block not in self.blocks:
            self.blocks[block] = self.n_inv
            self.n_inv += n_inv
            pro_ins = ", ".join(self.ref(a) if self.src[a][0] == "inv" else "V0" for a in i)
            self.prologue.append(f"{{ vd ci[{max(1, len(i))}] = {{{pro_ins}}}; {cname}_pro(ci, inv + {self.blocks[block]}); }}")
        ins = ", ".join(self.ref(a) for a in i)
        outs = "".join(f" w{slot} = co[{j}];" for j, slot in enumerate(o) if slot >= 0)
        self.body.append(f"{{ vd ci[{max(1, len(i))}] = {{{ins}}}; vd co[{max(1, len(o))}]; "
                         f"{cname}(ci, co, inv + {self.blocks[block]});{outs} }}")
        for slot in o:
            if slot >= 0:
                self.src[slot] = ("w", slot)
                self.used.add(slot)
                self._wrote(slot)


def _offsets(sizes) -> List[int]:
    out, o = [], 0
    for n in sizes:
        out.append(o)
        o += n
    return out


def callee_source(fn: ca.Function, callees: dict, fixed: Sequence[int] = ()) -> Tuple[str, int]:
    """``(C name, invariant slots)`` of ``fn``'s SIMD form with the flat inputs ``fixed`` constant along a
    run, emitting its definition into ``callees`` on first use.

    Two functions: ``NAME_pro(in, inv)`` fills the ``inv`` block (constants and what depends on the
    ``fixed`` inputs only; called once per run group) and ``NAME(in, out, inv)`` the rest.
    """
    key = (fn.name(), tuple(sorted(fixed)))
    if key in callees:
        return callees[key][0], callees[key][2]
    if not fn.is_a("SXFunction"):
        raise ValueError(f"soa_source: call of {fn.name()}, not an SX Function")
    io = (_offsets([fn.nnz_in(j) for j in range(fn.n_in())]), _offsets([fn.nnz_out(j) for j in range(fn.n_out())]))
    prog = SoaProgram((), fixed, callees, io)
    for j in range(fn.n_instructions()):
        prog.add(fn, j)
    cname = f"fjm_fn{len(callees)}"
    decl = ", ".join(f"w{j}" for j in sorted(prog.used)) or "w_unused"
    text = (f"/* {fn.name()} */\nstatic void {cname}_pro(const vd* restrict in, vd* restrict inv) {{\n  (void)in;"
            + "".join("\n  " + ln for ln in prog.prologue) + "\n}\n"
            f"static void {cname}(const vd* restrict in, vd* restrict out, const vd* restrict inv) {{\n"
            f"  vd {decl};" + "".join("\n  " + ln for ln in prog.body) + "\n}\n")
    callees[key] = (cname, text, prog.n_inv)
    return cname, prog.n_inv


def simd_template() -> Template:
    """The fixed C text of the SIMD batch (``simd_template.c``: vector helpers, prologue and
    step frames, the OpenMP driver ``fjm_sampled_batch_soa``) with ``$`` placeholders."""
    return Template(resources.files(__package__).joinpath("simd_template.c").read_text(encoding="utf-8"))


def passthrough_entries(step: ca.Function) -> List[int]:
    """The entries ``i`` of output 0 that are input 0's entry ``i`` itself (no operation between them).

    Found on the instruction list: a work slot remembers which entry of input 0 it holds until another
    instruction overwrites it. In the sampled step these are the TRUE parameters and the gains riding
    in the controller state: constant along a run.
    """
    holds: Dict[int, int] = {}
    out = []
    for k in range(step.n_instructions()):
        op, i, o = step.instruction_id(k), step.instruction_input(k), step.instruction_output(k)
        if op == ca.OP_OUTPUT:
            if o[0] == 0 and holds.get(i[0]) == o[1]:
                out.append(int(o[1]))
            continue
        for slot in o:
            holds.pop(slot, None)
        if op == ca.OP_INPUT and i[0] == 0:
            holds[o[0]] = int(i[1])
    return out


def soa_source(step: ca.Function, lanes: int, varying=(0,), invariant_from: int = None) -> str:
    """C source of ``step`` evaluated on ``lanes`` runs at once (inputs in ``varying`` per lane).

    GCC vector extensions: every SX instruction becomes one statement on a vector of
    ``lanes`` doubles (compiled to AVX-512/AVX2/SSE2 instructions); sin/cos and friends
    go through short lane loops that gcc maps to glibc's vector math (libmvec).
    Defines ``fjm_prologue(acc, inv)``, ``fjm_step_soa(inv, arg, res)`` and the driver
    ``fjm_sampled_batch_soa`` (the noise of each lane generated in C); varying inputs and every
    output are laid out ``[nz][lane]``.
    Entries ``>= invariant_from`` of input 0 (the TRUE parameters riding in the accumulator)
    and the entries the step passes through unchanged (:func:`passthrough_entries`: the
    parameters, the gains riding in the controller state) are constant along a run: every
    instruction that depends on them and constants only is hoisted into the prologue (once
    per run group, not once per step), a division by such a value becomes a multiplication
    by its reciprocal (rounding may differ by one ulp), and a passed-through entry is never
    stored (the driver starts both accumulator buffers equal).
    """
    same = passthrough_entries(step)
    tail = range(invariant_from, step.nnz_in(0)) if invariant_from is not None else ()
    prog = SoaProgram(varying, set(tail) | set(same), passthrough=same)
    for k in range(step.n_instructions()):
        prog.add(step, k)
    return simd_template().substitute(
        lanes=int(lanes), noise=noise_source(), n_inv=max(1, prog.n_inv),
        callees="".join(entry[1] for entry in prog.callees.values()),
        prologue="".join("\n  " + ln for ln in prog.prologue),
        declarations=", ".join(f"w{j}" for j in sorted(prog.used)) or "w_unused",
        body="".join("\n  " + ln for ln in prog.body))


def cpu_flags() -> set:
    """The CPU feature flags of this machine (``/proc/cpuinfo``; empty set if unknown)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for ln in fh:
                if ln.startswith("flags"):
                    return set(ln.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def vector_isa() -> tuple:
    """``(name, flags)``: the instruction set of the SIMD batch, chosen from THIS machine's CPU.

    ``name`` is ``avx512``, ``avx2``, ``sse2`` or ``generic``; the flags are part of
    the cache key, so a machine with another instruction set never loads a library
    built for this one.
    """
    cpu = cpu_flags()
    if {"avx512f", "avx512dq"} <= cpu:
        return "avx512", ("-mavx512f", "-mavx512dq", "-mprefer-vector-width=512")
    if "avx2" in cpu:
        return "avx2", ("-mavx2",)
    if "sse2" in cpu:
        return "sse2", ()
    return "generic", ()


def sampled_simd_runner(step: ca.Function, n_par: int, nm: int, flags: Sequence[str], lanes: Optional[int],
                        parallel: bool = True):
    """Compile (cached) a :func:`~fjm_runtime.batch.sampled.sampled_metric_step` in SIMD form (driver
    ``fjm_sampled_batch_soa``: the noise generated per lane in C); the last ``n_par`` accumulator
    entries (TRUE parameters) are hoisted into the prologue."""
    lanes = int(lanes) if lanes else 8
    isa, vflags = vector_isa()
    extra = ("-fno-math-errno", "-ffp-contract=off") + (("-fopenmp",) if parallel else ()) + vflags
    source = soa_source(step, lanes, varying=(0, 2), invariant_from=step.size1_in(0) - n_par)
    so = compile_library(source, "fjm_sampled_batch_soa", tuple(flags) + extra)
    return SampledBatchRunner(so, step.size1_in(0), step.size1_in(1), nm, step.size1_in(3), lanes, isa,
                              openmp=parallel)


def simd_runner_or_reason(step: ca.Function, n_par: int, parallel: bool, nm: int):
    """``(runner, None)`` with the SIMD form of ``step`` (a sampled metric step with ``nm`` noise
    channels), or ``(None, reason)`` when it cannot be used.

    Reasons: the step exceeds :data:`SIMD_MAX_INSTRUCTIONS`, an operation
    :func:`soa_source` does not support, or a failed build (the message is kept).
    """
    if step.n_instructions() > SIMD_MAX_INSTRUCTIONS:
        return None, (f"the step has {step.n_instructions()} SX instructions > "
                      f"SIMD_MAX_INSTRUCTIONS = {SIMD_MAX_INSTRUCTIONS}")
    try:
        return sampled_simd_runner(step, n_par, nm, DEFAULT_FLAGS, None, parallel), None
    except (CompileError, ValueError) as exc:
        return None, f"SIMD build failed: {type(exc).__name__}: {str(exc)[:2000]}"
