"""What ``fjm export controller`` refuses before writing C: an unverified design, a C name that is not
one, predictor substeps beyond what straight-line C holds, numbers the double and float C cannot hold.

Every refusal is one :class:`~fjm_runtime.validation.FjmValueError` line naming the flag (or the design
key), the value and the accepted range.
"""
from __future__ import annotations

import math
import re
from typing import Iterable, Optional

from ..validation import PARAMETER_MAGNITUDE, FjmValueError, check_magnitudes

__all__ = ["C_VALUE_RANGE", "GAIN_MAX", "MAX_NAME_LENGTH", "MAX_SUBSTEPS", "c_name", "check_c_values",
           "check_rule_substeps", "check_substeps", "check_verified", "default_c_name", "verification_text"]

#: Most RK4 substeps per sample of the exported predictor. The step is straight-line C, its size grows
#: with the substeps (link1: 2.9 MB of C at 10000); the substeps rule gives 11 for the Panda at 1 kHz
#: (14 for panda_hd), so 1000 leaves a 70x margin for a stiffer arm.
MAX_SUBSTEPS = 1000
#: Magnitude range of every parameter and gain written into the C (SI units): a physical arm's values lie
#: well inside, and the law's products of a few of them stay finite and normal in float (FLT_MAX 3.4e38,
#: smallest normal 1.2e-38). Zero is allowed (no friction, no payload).
C_VALUE_RANGE = PARAMETER_MAGNITUDE
#: Largest gain magnitude: the law's polynomial coefficients reach lam^4, with lam <= pi x rate (the
#: Nyquist pole) that is 1e18 at 10 kHz; float holds 3.4e38.
GAIN_MAX = 1e20
#: Longest C prefix (the longest symbol adds ``_float_ctrl_reset_sparsity_out``, 31 characters).
MAX_NAME_LENGTH = 64
#: Words a prefix may not be: the C++ class header opens ``namespace <name>``.
_KEYWORDS = frozenset("""alignas alignof and and_eq asm auto bitand bitor bool break case catch char char8_t char16_t
char32_t class compl concept const consteval constexpr constinit const_cast continue co_await co_return co_yield
decltype default delete do double dynamic_cast else enum explicit export extern false float for friend goto if
inline int long mutable namespace new noexcept not not_eq nullptr operator or or_eq private protected public
register reinterpret_cast requires restrict return short signed sizeof static static_assert static_cast struct
switch template this thread_local throw true try typedef typeid typename union unsigned using virtual void
volatile wchar_t while xor xor_eq null jac hess""".split())
_NAME = re.compile(r"^[A-Za-z](?:_?[A-Za-z0-9])*$")


def c_name(text: str) -> str:
    """``--name`` as given, when it is a usable C prefix.

    Raises
    ------
    FjmValueError
        Not a letter followed by letters, digits and single underscores (no trailing underscore), longer
        than :data:`MAX_NAME_LENGTH`, or a C/C++ keyword.
    """
    name = str(text)
    if not _NAME.match(name) or len(name) > MAX_NAME_LENGTH or name in _KEYWORDS:
        raise FjmValueError(f"--name {text!r}: expected a C identifier of 1..{MAX_NAME_LENGTH} characters: a letter, "
                            "then letters, digits and single underscores, not ending in _ and not a C/C++ keyword "
                            "(every symbol of the library starts with it)")
    return name


def default_c_name(text: str) -> str:
    """A usable C prefix made from ``text`` (a model name may hold ``-`` or start with a digit)."""
    name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", str(text))).strip("_")
    name = name if name[:1].isalpha() else f"ctrl_{name}".rstrip("_")
    name = name[:MAX_NAME_LENGTH].rstrip("_")
    return f"{name}_ctrl" if name in _KEYWORDS else name


def check_substeps(substeps, predicting: bool) -> Optional[int]:
    """``--substeps`` as an int (None: the rule's), refused out of range or when the design does not predict."""
    if substeps is None:
        return None
    ok = isinstance(substeps, (int, float)) and not isinstance(substeps, bool) and math.isfinite(substeps)
    shown = f"{substeps:g}" if ok else repr(substeps)
    if not (ok and float(substeps).is_integer() and 1 <= substeps <= MAX_SUBSTEPS):
        raise FjmValueError(f"--substeps {shown}: expected an integer 1..{MAX_SUBSTEPS} (RK4 substeps per sample "
                            "of the predictor; the exported step is straight-line C)")
    if not predicting:
        raise FjmValueError(f"--substeps {shown}: the design does not predict (predict off or delay 0), so the "
                            f"library integrates nothing; expected no --substeps (1..{MAX_SUBSTEPS} only with "
                            "prediction)")
    return int(substeps)


def check_rule_substeps(substeps: int, model_name: str) -> None:
    """Refuse a substeps rule (the plant's fastest mode) beyond :data:`MAX_SUBSTEPS`."""
    if substeps > MAX_SUBSTEPS:
        raise FjmValueError(f"model {model_name}: the substeps rule needs {substeps} RK4 substeps per sample for the "
                            f"predictor; expected at most {MAX_SUBSTEPS} (a stiffness and inertia in a physical "
                            "range, or a higher control rate)")


def check_c_values(names: Iterable[str], values: Iterable[float], where: str, hi: float = C_VALUE_RANGE[1]) -> None:
    """Refuse a value of magnitude outside ``0`` or ``[C_VALUE_RANGE[0], hi]``, naming ``where`` (a prefix of
    the name, e.g. ``"--params p.toml: "``), the name and the value."""
    check_magnitudes(names, values, where, hi, "SI units: no physical arm's value lies beyond, and float still "
                                               "holds the law's products")


def check_verified(meets: Optional[bool], where: str, unverified: bool) -> None:
    """Refuse a design whose search found that it misses its thresholds (``"meets": false``)."""
    if meets is False and not unverified:
        raise FjmValueError(f"{where}: \"meets\": false (the design misses its thresholds, see its \"misses\"); "
                            "expected a design that meets them (--unverified exports it, labelled unverified)")


def verification_text(meets: Optional[bool], report: Optional[dict] = None) -> str:
    """One line for the README and the header: what the design's search found (``report``: the design
    file's other keys, e.g. an older search's ``draws`` and ``worst_case``)."""
    if meets is True:
        return "verified: the design meets the thresholds of its search (fjm design, \"meets\": true)"
    if meets is False:
        return ("UNVERIFIED: the design MISSES the thresholds of its search (\"meets\": false); exported with "
                "--unverified")
    report = report or {}
    worst = report.get("worst_case")
    if isinstance(worst, dict) and isinstance(worst.get("rms_second_half"), list) and report.get("draws"):
        return (f"searched by fjm design over {report['draws']} plant draws (worst second-half RMS "
                f"{max(worst['rms_second_half']):.3g} rad, {worst.get('diverged', '?')} diverged); the file records "
                "no \"meets\" verdict: compare its worst case with your thresholds")
    return "not verified: the design records no search (not from fjm design); check it with fjm analyze"
