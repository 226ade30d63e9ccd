"""A C function in CasADi's calling convention, called through ctypes (the generated-C tests)."""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np


class CFunction:
    """One generated C function called through ctypes in CasADi's calling convention."""

    def __init__(self, lib: ctypes.CDLL, name: str, real):
        self.name, self.real = name, real
        ll = ctypes.c_longlong
        self.fn = getattr(lib, name)
        self.fn.restype = ctypes.c_int
        for suffix, restype in (("_n_in", ll), ("_n_out", ll), ("_checkout", ctypes.c_int)):
            getattr(lib, name + suffix).restype = restype
        self.n_in = getattr(lib, name + "_n_in")()
        self.n_out = getattr(lib, name + "_n_out")()
        sp_in, sp_out = getattr(lib, name + "_sparsity_in"), getattr(lib, name + "_sparsity_out")
        sp_in.restype = sp_out.restype = ctypes.POINTER(ll)
        sp_in.argtypes = sp_out.argtypes = [ll]
        self.sparsity_in = [self._sparsity(sp_in(i)) for i in range(self.n_in)]
        self.sparsity_out = [self._sparsity(sp_out(i)) for i in range(self.n_out)]
        sizes = [ll() for _ in range(4)]
        work = getattr(lib, name + "_work")
        work.restype = ctypes.c_int
        assert work(*[ctypes.byref(s) for s in sizes]) == 0
        self.sz_arg, self.sz_res, self.sz_iw, self.sz_w = (int(s.value) for s in sizes)
        self.checkout = getattr(lib, name + "_checkout")
        self.release = getattr(lib, name + "_release")
        self.release.argtypes = [ctypes.c_int]

    @staticmethod
    def _sparsity(ptr) -> ca.Sparsity:
        """Decode CasADi's compressed sparsity: [nrow, ncol, 1] (dense) or [nrow, ncol, colind..., row...]."""
        nrow, ncol = int(ptr[0]), int(ptr[1])
        if ptr[2] == 1:
            return ca.Sparsity.dense(nrow, ncol)
        colind = [int(ptr[2 + j]) for j in range(ncol + 1)]
        row = [int(ptr[2 + ncol + 1 + k]) for k in range(colind[-1])]
        return ca.Sparsity(nrow, ncol, colind, row)

    def __call__(self, *inputs, skip_out=()) -> list:
        """The outputs as dense arrays. An input given as None and the outputs numbered in ``skip_out`` are
        passed as null pointers (CasADi's "absent"); output buffers start as NaN, so an entry the function
        did not write shows."""
        real, P = self.real, ctypes.POINTER(self.real)
        bufs = [None if v is None else (real * sp.nnz())(*np.asarray(v, dtype=float).ravel(order="F"))
                for v, sp in zip(inputs, self.sparsity_in)]
        outs = [(real * sp.nnz())(*[np.nan] * sp.nnz()) for sp in self.sparsity_out]
        arg = (P * max(self.sz_arg, 1))(*[None if b is None else ctypes.cast(b, P) for b in bufs])
        res = (P * max(self.sz_res, 1))(*[None if i in skip_out else ctypes.cast(b, P) for i, b in enumerate(outs)])
        iw = (ctypes.c_longlong * max(self.sz_iw, 1))()
        w = (real * max(self.sz_w, 1))()
        mem = self.checkout()
        try:
            flag = self.fn(arg, res, iw, w, ctypes.c_int(mem))
        finally:
            self.release(mem)
        assert flag == 0, f"{self.name} returned {flag}"
        return [ca.DM(sp, list(o)).full() for o, sp in zip(outs, self.sparsity_out)]
