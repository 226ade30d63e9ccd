"""Input checks shared by the runtime: every error names the argument, the value and what was expected."""

from __future__ import annotations

import math
from typing import Mapping, Sequence, Tuple, Union

import numpy as np


#: What a stale generated model directory asks for, for a built-in model and for a user's model file.
REDERIVE = "re-run make derive (a built-in model) or fjm derive --model-file FILE --out DIR (your model file)"


class FjmValueError(ValueError):
    """A bad input to fjm (subclass of ValueError so callers may catch either)."""


#: Magnitude range of a parameter value fjm takes (SI units): a physical arm's values lie well inside
#: (motor inertias ~1e-6 kg m^2, stiffnesses ~1e6 N m/rad); zero is allowed (no friction, no payload).
PARAMETER_MAGNITUDE = (1e-12, 1e12)


def check_magnitudes(names, values, where: str, hi: float = PARAMETER_MAGNITUDE[1],
                     why: str = "SI units: no physical arm's value lies beyond") -> None:
    """Refuse a value of magnitude outside ``0`` or ``[PARAMETER_MAGNITUDE[0], hi]``, in one line naming
    ``where`` (a prefix of the name, e.g. ``"--params p.toml: "``), the name, the value and ``why``."""
    lo = PARAMETER_MAGNITUDE[0]
    for name, v in zip(names, values):
        v = float(v)
        if not (math.isfinite(v) and (v == 0.0 or lo <= abs(v) <= hi)):
            raise FjmValueError(f"{where}{name} = {v:g}: expected 0 or {lo:g} <= |value| <= {hi:g} ({why})")


ArrayLike = Union[Sequence[float], np.ndarray]


def as_vector(name: str, value, length: int) -> np.ndarray:
    """Return ``value`` as a finite float vector of shape ``(length,)``.

    Raises
    ------
    FjmValueError
        If the shape differs, any entry is NaN/inf, text, or complex (a real array is
        expected; the imaginary part is never dropped silently).
    """
    if _is_complex(value):
        raise FjmValueError(f"{name}: expected a real array of shape ({length},), got complex values {value!r}")
    try:
        if isinstance(value, (str, bytes)) or any(isinstance(v, (str, bytes)) for v in np.ravel(
                np.asarray(value, dtype=object))):
            raise TypeError("text is not a number")
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FjmValueError(f"{name}: expected a numeric array of shape ({length},), got {value!r}") from exc
    if arr.ndim == 2 and 1 in arr.shape and arr.size == length:
        arr = arr.reshape(length)
    if arr.shape != (length,):
        raise FjmValueError(f"{name}: expected shape ({length},), got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FjmValueError(f"{name}: entry {i} is {arr[i]}; expected finite values")
    return arr


# Spatial models: inertia tensor of a link about its centre of mass (``symbolic = [...]``).
_TENSOR = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")

#: Domain string (manifest ``parameters[].domain``, derive.core.domains) -> (test, expectation).
_DOMAIN_TESTS = {">0": (lambda v: v > 0, "> 0"), ">=0": (lambda v: v >= 0, ">= 0")}


def check_domains(info: Mapping, names: Sequence[str], values: np.ndarray, arg: str = "p") -> None:
    """Raise a one-line :class:`FjmValueError` for the first value outside its parameter's domain.

    Parameters
    ----------
    info : mapping
        ``name -> ParameterInfo`` (:func:`fjm_runtime.drives.read_parameter_info`: ``domain``, ``unit``,
        ``meaning``); names it lacks are not checked.
    names : sequence of str
    values : ndarray, shape (len(names),)
    arg : str
        The argument's name in the message.
    """
    for name, v in zip(names, values):
        p = info.get(name)
        test = None if p is None else _DOMAIN_TESTS.get(p.domain)
        if test is not None and not test[0](v):
            unit = f" {p.unit}" if p.unit else ""
            raise FjmValueError(f"{arg}[{name!r}] = {v}: expected {test[1]}{unit} ({p.meaning})")


def _check_three_segment(names: Sequence[str], values: np.ndarray, drives: Sequence, arg: str) -> None:
    """The three-segment spring's relations (derive/core/spring_laws.py): stiffening segments,
    ordered torque breakpoints, blend windows that neither reach zero nor overlap."""
    for d in drives:
        if d.spring_law == "three_segment":
            keys = [names[i] for i in d.spring]
            joint = f"; joint {d.joint + 1}" if len(drives) > 1 else ""
            _check_one_three_segment(*(float(values[i]) for i in d.spring), arg, keys, joint)


def _check_one_three_segment(K1, K2, K3, T1, T2, w, arg: str, keys: Sequence[str], joint: str) -> None:
    """One joint's three-segment relations (``keys``: its coefficient names in the law's order)."""
    if not K1 <= K2 <= K3:
        raise FjmValueError(f"{arg}{keys[:3]} = {[K1, K2, K3]}: expected K_1 <= K_2 <= K_3 (N m/rad; "
                            f"a harmonic drive stiffens{joint})")
    if not T1 < T2:
        raise FjmValueError(f"{arg}{keys[3:5]} = {[T1, T2]}: expected T_1 < T_2 (N m, torque breakpoints{joint})")
    limit = min(2 * T1 / K1, (T2 - T1) / K2)
    if not w <= limit:
        raise FjmValueError(f"{arg}[{keys[5]!r}] = {w}: expected <= {limit:.6g} rad (min(2 phi_1, phi_2 - phi_1) "
                            f"at these breakpoints: the blends must not reach phi = 0 nor overlap{joint})")


def check_physical(names: Tuple[str, ...], values: np.ndarray, arg: str = "p", info: Mapping = None,
                   drives: Sequence = ()) -> None:
    """Reject non-physical parameter values.

    Each value must lie in its parameter's domain (``info``, from the manifest: masses, lengths,
    inertias, stiffnesses and motor inertias > 0; damping, friction levels and gravity >= 0; ...);
    a three-segment spring of ``drives`` must stiffen with ordered breakpoints; a centre of mass must
    lie on its link (``r_i <= l_i``); each link's tensor ``ixx_<link> .. izz_<link>`` must be
    positive definite.

    Parameters
    ----------
    names : tuple of str
    values : ndarray, shape (len(names),)
    arg : str
    info : mapping, optional
        ``name -> ParameterInfo`` (:attr:`fjm_runtime.model.Model.parameter_info`); None: no domain check.
    drives : sequence of Drive, optional
        :attr:`fjm_runtime.model.Model.drives`.
    """
    lookup = dict(zip(names, values))
    check_domains(info or {}, names, values, arg)
    _check_three_segment(names, values, drives, arg)
    for name in names:
        if name.startswith("ixx_"):
            link = name[4:]
            keys = [f"{f}_{link}" for f in _TENSOR]
            if all(k in lookup for k in keys):
                xx, xy, xz, yy, yz, zz = (lookup[k] for k in keys)
                tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], dtype=float)
                if not np.all(np.linalg.eigvalsh(tensor) > 0):
                    raise FjmValueError(
                        f"{arg}[{', '.join(repr(k) for k in keys)}] = {[xx, xy, xz, yy, yz, zz]}: "
                        f"expected a positive definite inertia tensor of link {link!r}")
    for name, v in lookup.items():
        if name.startswith("r") and name[1:].isdigit() and f"l{name[1:]}" in lookup:
            length = lookup[f"l{name[1:]}"]
            if v > length:
                raise FjmValueError(
                    f"{arg}[{name!r}] = {v}: expected <= l{name[1:]} = {length} "
                    "(the centre of mass must lie on the link)")


def params_vector(names: Tuple[str, ...], defaults: Mapping[str, float], p, arg: str = "p", info: Mapping = None,
                  drives: Sequence = ()) -> np.ndarray:
    """Convert ``p`` (array in ``names`` order, or dict) to a vector checked by :func:`check_physical`
    (``info``, ``drives``: its domains and drive relations).

    A dict may omit keys (they take their defaults) but must not contain
    unknown ones.
    """
    if p is None:
        values = np.array([defaults[k] for k in names], dtype=float)
    elif isinstance(p, Mapping):
        unknown = sorted(set(p) - set(names))
        if unknown:
            raise FjmValueError(
                f"{arg}: unknown parameter name(s) {unknown}; expected names among {list(names)}")
        for k in names:
            if k in p and not _is_number(p[k]):
                raise FjmValueError(f"{arg}[{k!r}] = {p[k]!r}: expected a real number")
            if k in p and not np.isfinite(float(p[k])):
                raise FjmValueError(f"{arg}[{k!r}] = {p[k]}: expected a finite value")
        values = [float(p.get(k, defaults[k])) for k in names]
        values = as_vector(arg, values, len(names))
    else:
        values = as_vector(arg, p, len(names))
    check_physical(names, values, arg, info, drives)
    return values


def _is_complex(value) -> bool:
    """True if ``value`` (array, sequence or scalar) holds complex numbers."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        return False
    if np.iscomplexobj(arr):
        return True
    return arr.dtype == object and any(isinstance(v, (complex, np.complexfloating)) for v in arr.ravel())


def _is_number(v) -> bool:
    if _is_complex(v):
        return False
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return not isinstance(v, (str, bytes))


def joint_vector(value, n: int, field: str, minimum: float = None, strict: bool = False) -> np.ndarray:
    """A per-joint setting as shape ``(n,)``: a scalar is broadcast to every joint.

    Parameters
    ----------
    value : float or array_like, shape (n,)
    n : int
        Number of joints.
    field : str
        Name used in error messages.
    minimum : float, optional
        Lower bound: values must be ``>= minimum`` (``> minimum`` if ``strict``).

    Raises
    ------
    ValueError
        Wrong shape, non-finite values, or values below the bound.
    """
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{field} with shape {a.shape}: expected a scalar or shape ({n},)")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{field} = {a.tolist()}: expected finite values")
    if minimum is not None:
        bad = a <= minimum if strict else a < minimum
        if np.any(bad):
            raise ValueError(f"{field} = {a.tolist()}: expected values {'>' if strict else '>='} {minimum:g}")
    return a
