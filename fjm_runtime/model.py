"""Load generated models: ``load(name) -> Model`` (the contract of docs/design.md, "Runtime contract").

The runtime only deserializes the CasADi Functions written by ``make derive``;
it never imports SymPy.
"""

from __future__ import annotations

import json
import os
import shlex
from functools import lru_cache
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import casadi as ca
import numpy as np

from .drives import Drive, ParameterInfo, read_drives, read_parameter_info
from .robot_facts import JointLimits, Task, joint_limits, task_from_manifest
from .validation import REDERIVE, FjmValueError, as_vector, params_vector

#: Quantities every generated model provides (file ``<name>.casadi``).
QUANTITIES = ("f", "g", "ad", "T", "alpha", "beta", "energy", "inertia")
#: Quantities of a complete model (manifest ``"form": "complete"``; docs/complete-model.md).
COMPLETE_QUANTITIES = ("f", "g", "energy", "inertia", "coupling")


#: Environment variable naming a directory of user models (``<dir>/<model>/manifest.json``).
USER_MODELS_ENV = "FJM_GENERATED"


def generated_root() -> Path:
    """Directory holding the built-in models (``<model>/manifest.json``).

    The copy shipped inside the installed package (``fjm_runtime/generated``), else
    the repository's ``generated/``. User models (``$FJM_GENERATED``) are added on top
    by :func:`model_roots`.
    """
    here = Path(__file__).resolve().parent
    for cand in (here / "generated", here.parent / "generated"):
        if cand.is_dir():
            return cand
    return here.parent / "generated"


def user_models_root() -> Optional[Path]:
    """The directory named by ``$FJM_GENERATED``, or None when the variable is unset or empty.

    Raises
    ------
    FjmValueError
        The variable names a path that is not a directory (the message names both).
    """
    env = os.environ.get(USER_MODELS_ENV)
    if not env:
        return None
    root = Path(env)
    if not root.is_dir():
        raise FjmValueError(f"{USER_MODELS_ENV} = {env!r}: no such directory (expected a directory of "
                            "generated models, <dir>/<model>/manifest.json); set it to one or unset it")
    return root


def model_roots() -> List[Path]:
    """Where models are looked up, first match wins: ``$FJM_GENERATED`` (if set), then the built-in ones.

    A user model with the name of a built-in model therefore replaces it; every other
    built-in model stays available.
    """
    user = user_models_root()
    return ([user] if user is not None else []) + [generated_root()]


def _models_in(root: Path) -> List[str]:
    if not root.is_dir():
        return []
    return sorted(d.name for d in root.iterdir() if (d / "manifest.json").is_file())


def available_models(root: Optional[Path] = None) -> List[str]:
    """Names of the models found under ``root`` (default: every root of :func:`model_roots`), sorted."""
    roots = [Path(root)] if root is not None else model_roots()
    return sorted({name for r in roots for name in _models_in(r)})


def model_directory(name: str) -> Optional[Path]:
    """The directory of model ``name``: the first root of :func:`model_roots` that has it, or None."""
    for root in model_roots():
        if (root / name / "manifest.json").is_file():
            return root / name
    return None


def _read_function(path: Path) -> ca.Function:
    if not path.is_file():
        raise FjmValueError(f"{path}: missing generated file (the model directory is incomplete; "
                            "regenerate it)")
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    if len(lines) != 1:
        raise FjmValueError(f"{path}: corrupt generated file (expected one serialized Function line)")
    return ca.Function.deserialize(lines[0])


class Model:
    """A generated flexible-joint model.

    Attributes
    ----------
    name : str
    n : int
        Number of links.
    nx : int
        State dimension, ``4 n``; ``x = [q; dq; q_m; dq_m]``.
    param_names : tuple of str
    default_params : dict str -> float
    manifest : dict
        The model's ``manifest.json``.
    effort_limits, velocity_limits : numpy.ndarray (n,) or None
        The URDF's ``<limit effort velocity>`` per joint (N m, rad/s), None for models without them.
    position_limits : numpy.ndarray (n, 2) or None
        The URDF's ``[lower, upper]`` per joint (rad).
    limits : fjm_runtime.robot_facts.JointLimits
        The limits a design uses: the model file's ``[limits]`` over the URDF's (``inf``: none).
    task : fjm_runtime.robot_facts.Task or None
        The task of the model's demo and design (its model file's ``[task]``).

    Every method takes ``x`` (length 4n) and ``p`` (array in ``param_names``
    order, dict with defaults for missing keys, or None for all defaults) and
    returns NumPy arrays.
    """

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        manifest = self.directory / "manifest.json"
        if not manifest.is_file():
            what = "no such directory" if not self.directory.is_dir() else "no manifest.json in it"
            given = directory if isinstance(directory, str) else str(self.directory)  # as typed: Path drops a '/'
            raise FjmValueError(f"model directory {given!r}: {what} (expected a generated "
                                "model directory, <dir>/manifest.json)")
        try:
            self.manifest = json.loads(manifest.read_text())
        except ValueError as exc:
            raise FjmValueError(f"{manifest}: not valid JSON ({exc})") from None
        self.name: str = self.manifest["model"]
        self.n: int = int(self.manifest["n"])
        self.nx: int = int(self.manifest["nx"])
        self.param_names: Tuple[str, ...] = tuple(p["name"] for p in self.manifest["parameters"])
        self.default_params: Dict[str, float] = {
            p["name"]: float(p["default"]) for p in self.manifest["parameters"]}
        #: ``name -> ParameterInfo`` (unit, meaning, domain, drive role) of every parameter.
        self.parameter_info: Dict[str, ParameterInfo] = read_parameter_info(self.manifest)
        self._drives = read_drives(self.manifest, self.param_names) if "drives" in self.manifest else None
        #: ``"complete"`` (rotor gyroscopics, no static feedback linearization) or ``"reduced"``.
        self.form: str = self.manifest.get("form", "reduced")
        self.reduced_model: Optional[str] = self.manifest.get("reduced_model")
        names = COMPLETE_QUANTITIES if self.form == "complete" else QUANTITIES
        self.functions: Dict[str, ca.Function] = {
            q: _read_function(self.directory / f"{q}.casadi") for q in names}
        self._controls: Optional[Dict[str, ca.Function]] = None
        self._torque: Optional[Dict[str, ca.Function]] = None

    @property
    def drives(self) -> Tuple[Drive, ...]:
        """One :class:`~fjm_runtime.drives.Drive` per elastic joint, in q order (``manifest["drives"]``):
        indices of its spring coefficients, rotor inertia, damping, friction and gear ratio."""
        # an older manifest has none: read_drives refuses it in its one line
        return read_drives(self.manifest, self.param_names) if self._drives is None else self._drives

    @property
    def controls(self) -> Dict[str, ca.Function]:
        """The emitted control laws: ``"control_<kind>"`` (and ``"control_<kind>_zdot"``) -> Function.

        Signatures and the ``z``/``gains`` layouts: ``manifest["controls"]`` and the
        header of ``<model>.h``. Read on first use.
        """
        if self._controls is None:
            if self.form == "complete":
                self._require("controls")
            entries = self.manifest.get("controls")
            if not entries:
                raise FjmValueError(f"model {self.name}: {self.directory} has no emitted control laws "
                                    f"(generated by an older fjm); {REDERIVE}")
            out = {}
            for kind, e in entries.items():
                out[f"control_{kind}"] = _read_function(self.directory / e["casadi_file"])
                if "zdot" in e:
                    out[f"control_{kind}_zdot"] = _read_function(self.directory / e["zdot"]["casadi_file"])
            self._controls = out
        return self._controls

    @property
    def torque_functions(self) -> Dict[str, ca.Function]:
        """The torque-coordinate functions of ``m = [q; dq; tau_J; dtau_J; dq_m]`` (5n) and ``p``:
        ``"T_tau"`` (4n), ``"alpha_tau"`` (n), ``"beta_tau"`` (n, n) (``manifest["torque_functions"]``,
        docs/torque-sensing.md). Read on first use.
        """
        if self._torque is None:
            entries = self.manifest.get("torque_functions")
            if not entries:
                raise FjmValueError(f"model {self.name}: {self.directory} has no torque-sensed functions "
                                    f"(generated by an older fjm, or a complete model); {REDERIVE}")
            self._torque = {name: _read_function(self.directory / e["casadi_file"]) for name, e in entries.items()}
        return self._torque

    @property
    def spring_functions(self) -> Optional[Dict[str, ca.Function]]:
        """The model's spring law: ``"spring"`` ``(phi, p) -> (psi, dpsi, ddpsi)`` and ``"spring_inverse"``
        ``(tau_J, p) -> phi_J`` (``manifest["springs"]``; a linear spring's are ``K phi`` and ``tau_J / K``);
        None for a directory generated by an older fjm (:func:`fjm_runtime.drives.model_springs` says so)."""
        entries = (self.manifest.get("springs") or {}).get("functions")
        if not entries:
            return None
        if getattr(self, "_springs", None) is None:
            self._springs = {name: _read_function(self.directory / e["casadi_file"]) for name, e in entries.items()}
        return self._springs

    @property
    def feedforward_function(self) -> ca.Function:
        """``<model>_feedforward(r, p) -> (tau_Jd, theta_d, dtheta_d, ddtheta_d, u_ff)`` (``manifest["feedforward"]``).

        The flatness feedforward of the nominal model: ``r`` (5n) the reference rows stacked, ``p`` the
        nominal parameters; each output (n,). Read on first use.
        """
        entry = self.manifest.get("feedforward")
        if not entry:
            why = ("a complete model has none (use its reduced model's)" if self.form == "complete"
                   else f"generated by an older fjm; {REDERIVE}")
            raise FjmValueError(f"model {self.name}: {self.directory} has no feedforward Function ({why})")
        if getattr(self, "_feedforward", None) is None:
            self._feedforward = _read_function(self.directory / entry["casadi_file"])
        return self._feedforward

    def feedforward(self, r, p=None) -> Tuple[np.ndarray, ...]:
        """The flatness feedforward along the reference ``r`` (:attr:`feedforward_function`).

        Parameters
        ----------
        r : array_like, shape (5, n) or (5n,)
            ``q_d, q_d', q_d'', q_d''', q_d''''`` (rad, rad/s, ..., rad/s^4), as a reference returns it.
        p : array, dict or None
            Nominal parameters.

        Returns
        -------
        tuple of numpy.ndarray, each (n,)
            ``tau_Jd`` (N m), ``theta_d`` (rad), ``dtheta_d`` (rad/s), ``ddtheta_d`` (rad/s^2), ``u_ff`` (N m).
        """
        fn = self.feedforward_function
        rv = as_vector("r", np.asarray(r, dtype=float).ravel(), 5 * self.n)
        return tuple(v.full().ravel() for v in fn(rv, self.params_array(p)))

    # -- joint limits stated by the URDF ----------------------------------------
    def _urdf_limit(self, key: str) -> Optional[np.ndarray]:
        """``manifest["source"]["limits"][key]`` as floats (n,), None where the model states none."""
        src = self.manifest.get("source")
        values = (src.get("limits") or {}).get(key) if isinstance(src, dict) else None
        if not values or all(v is None for v in values):
            return None
        if len(values) != self.n:
            raise FjmValueError(f"model {self.name}: manifest source.limits.{key} has {len(values)} entries, "
                                f"expected n = {self.n}; {REDERIVE}")
        return np.array([np.nan if v is None else float(v) for v in values])

    @property
    def effort_limits(self) -> Optional[np.ndarray]:
        """The URDF's ``<limit effort>`` per joint in q order, N m (link side), shape (n,); None if not stated.

        Exactly the URDF's numbers (``manifest["source"]["limits"]``): placeholders are kept (Baxter's
        head pan states 50000 N m) and it is the caller's choice what to do with them. A joint whose
        URDF states no effort while others do: ``inf`` (no limit stated). None for models not derived
        from a URDF (``link1``, ``planar<n>``) and for URDFs without ``<limit effort>``.
        """
        limits = self._urdf_limit("effort")
        return None if limits is None else np.where(np.isnan(limits), np.inf, limits)

    @property
    def velocity_limits(self) -> Optional[np.ndarray]:
        """The URDF's ``<limit velocity>`` per joint, rad/s, shape (n,) (``inf`` where not stated); None
        if the model states none (see :attr:`effort_limits`)."""
        limits = self._urdf_limit("velocity")
        return None if limits is None else np.where(np.isnan(limits), np.inf, limits)

    @property
    def position_limits(self) -> Optional[np.ndarray]:
        """The URDF's ``<limit lower upper>`` per joint, rad, shape (n, 2) as ``[lower, upper]``
        (``-inf, inf`` for a continuous joint); None if the model states none."""
        lower, upper = self._urdf_limit("lower"), self._urdf_limit("upper")
        if lower is None and upper is None:
            return None
        lower = np.full(self.n, np.nan) if lower is None else lower
        upper = np.full(self.n, np.nan) if upper is None else upper
        return np.column_stack([np.where(np.isnan(lower), -np.inf, lower), np.where(np.isnan(upper), np.inf, upper)])

    # -- the robot's own facts (its model file's [limits] and [task]) ------------
    @property
    def limits(self) -> JointLimits:
        """Joint limits (effort N m, velocity rad/s, torque_rate N m/s: (n,); position rad: (n, 2)), ``inf``
        where none is stated: the manifest's ``limits`` (the model file's ``[limits]`` over the URDF's), else
        the URDF's as :attr:`effort_limits`, :attr:`velocity_limits`, :attr:`position_limits` read them."""
        if getattr(self, "_limits", None) is None:
            self._limits = joint_limits(self.manifest, self.n, {
                "effort": self.effort_limits, "velocity": self.velocity_limits, "position": self.position_limits})
        return self._limits

    @property
    def task(self) -> Optional[Task]:
        """The task the model's files state for its demo and design (manifest ``task``); None if none."""
        if getattr(self, "_task", None) is None:
            self._task = task_from_manifest(self.manifest, self.n)
        return self._task

    def __repr__(self) -> str:
        return f"<fjm Model {self.name}: n={self.n}, nx={self.nx}, params={len(self.param_names)}>"

    # -- argument handling -------------------------------------------------
    def params_array(self, p=None, arg: str = "p") -> np.ndarray:
        """``p`` (array, dict or None) as a validated vector of shape ``(len(param_names),)``."""
        return params_vector(self.param_names, self.default_params, p, arg, self.parameter_info, self._drives or ())

    def state_array(self, x, arg: str = "x") -> np.ndarray:
        """``x`` as a validated vector of shape ``(nx,)``."""
        return as_vector(arg, x, self.nx)

    def _require(self, quantity: str) -> None:
        if quantity not in self.functions:
            raise FjmValueError(
                f"model {self.name} is a complete model (rotor spin coupling): it has no {quantity} (static "
                f"feedback linearization does not exist for it); use the laws of its reduced model "
                f"{self.reduced_model!r} (fjm_runtime.load({self.reduced_model!r})) with this model as the plant")

    def _eval(self, quantity: str, x, p) -> np.ndarray:
        self._require(quantity)
        xv = self.state_array(x)
        pv = self.params_array(p)
        return self.functions[quantity](xv, pv).full()

    # -- the contract ------------------------------------------------------
    def f(self, x, p=None) -> np.ndarray:
        """Drift ``f(x)``, shape (4n,)."""
        return self._eval("f", x, p).ravel()

    def g(self, x, p=None) -> np.ndarray:
        """Input matrix ``g(x)``, shape (4n, n)."""
        return self._eval("g", x, p)

    def ad(self, x, p=None) -> np.ndarray:
        """``[g, ad_f g, ad_f^2 g, ad_f^3 g]`` with ``ad_f v = (df/dx) v - (dv/dx) f``, shape (4n, 4n)."""
        return self._eval("ad", x, p)

    def T(self, x, p=None) -> np.ndarray:
        """Linearizing coordinates ``[y1; y2; y3; y4]``, shape (4n,)."""
        return self._eval("T", x, p).ravel()

    def alpha(self, x, p=None) -> np.ndarray:
        """``alpha(x)``, shape (n,); ``u = alpha + beta nu`` gives ``y4' = nu``."""
        return self._eval("alpha", x, p).ravel()

    def beta(self, x, p=None) -> np.ndarray:
        """``beta(x) = J_m K^-1 D(q)``, shape (n, n)."""
        return self._eval("beta", x, p)

    def energy(self, x, p=None) -> float:
        """Total mechanical energy (links, motors, springs, gravity), scalar."""
        return float(self._eval("energy", x, p)[0, 0])

    def inertia(self, x, p=None) -> np.ndarray:
        """Link inertia matrix ``D(q)``, shape (n, n); for a complete model the whole ``M(q)``, shape (2n, 2n)."""
        return self._eval("inertia", x, p)

    def coupling(self, x, p=None) -> np.ndarray:
        """Complete model only: the rotor spin coupling ``S(q)``, shape (n, n)."""
        return self._eval("coupling", x, p)

    def xdot(self, x, u, p=None) -> np.ndarray:
        """Open-loop dynamics ``f(x) + g(x) u``, shape (4n,)."""
        uv = as_vector("u", u, self.n)
        return self.f(x, p) + self.g(x, p) @ uv


@lru_cache(maxsize=None)
def _load_cached(directory: str) -> Model:
    return Model(directory)


def load(name: str) -> Model:
    """Load a generated model by name (``"link1"``, ``"planar1"`` .. ``"planar7"``, or a user model) or path.

    Names are looked up in ``$FJM_GENERATED`` first (user models; one there with a
    built-in name wins), then among the built-in models (:func:`model_roots`). A name
    with a path separator, or one that is no model's name but an existing directory, is a
    path (:func:`model_path`): a model directory (``<dir>/manifest.json``), the output
    directory of ``fjm derive --out DIR`` holding one model, or a model's manifest.json.

    Raises
    ------
    FjmValueError
        (a ``ValueError``) If no model of that name exists (the message lists the
        available ones and says that a path works), the path given does not hold a model
        (the message names it and what it holds), or ``$FJM_GENERATED`` is not a directory.
    """
    is_path = isinstance(name, os.PathLike) or (isinstance(name, str) and (
        os.sep in name or bool(os.altsep and os.altsep in name)))
    directory = None if is_path else (model_directory(name) if isinstance(name, str) and name else None)
    if directory is None and not is_path and isinstance(name, str) and name and Path(name).is_dir():
        is_path = True  # e.g. `fjm simulate build` inside the folder derive wrote to
    if is_path:
        return _load_cached(model_path(name))
    if directory is None:
        models = available_models()
        raise FjmValueError(
            f"unknown model {name!r}; available models: {', '.join(models) or '(none found)'}; or give the path "
            "of a derived model directory (`fjm derive --model-file FILE --out DIR` writes DIR/<name>)")
    return _load_cached(str(directory))


def _model_file_name(path: Path) -> str:
    """The ``[model] name`` of a model file (its first ``name = "..."`` line), ``<name>`` if unreadable."""
    import re
    try:
        found = re.search(r'^\s*name\s*=\s*"([A-Za-z_][A-Za-z0-9_]*)"', path.read_text(errors="replace"), re.M)
    except OSError:
        found = None
    return found.group(1) if found else "<name>"


def command_name(model) -> str:
    """How ``model`` is named on the command line: its name where :func:`load` finds it by name (a built-in
    or ``$FJM_GENERATED`` model), else the path of its directory (a user's derived model), quoted for a
    POSIX shell where it needs it (a space in the path)."""
    directory = getattr(model, "directory", None)
    name = str(getattr(model, "name", "MODEL"))
    if directory is None:
        return name
    try:
        found = model_directory(name)
    except FjmValueError:
        found = None
    if found is not None and Path(found).resolve() == Path(directory).resolve():
        return name
    return shlex.quote(str(directory))


def model_path(given) -> str:
    """The model directory a path names, as a string for :class:`Model`.

    ``given`` is a model directory (``manifest.json`` in it: returned resolved), a directory holding
    exactly one model directory (``fjm derive --out DIR`` for one model file), or a ``manifest.json``
    file (its directory). Anything else is returned as given, for :class:`Model` to refuse in one line.

    Raises
    ------
    FjmValueError
        A directory holding several models (the message lists them), or a model file (``.toml``: it is
        derived first) or a ``.urdf`` given instead of a derived model.
    """
    path = Path(given)
    if path.is_dir():
        if (path / "manifest.json").is_file():
            return str(path.resolve())
        inside = _models_in(path)
        if len(inside) == 1:
            return str((path / inside[0]).resolve())
        if inside:
            raise FjmValueError(f"model directory {str(given)!r}: holds {len(inside)} models ({', '.join(inside)}); "
                                f"expected one of them, e.g. {str(path / inside[0])!r}")
    elif path.is_file() and path.name == "manifest.json":
        return str(path.parent.resolve())
    elif path.is_file() and path.suffix.lower() == ".toml":
        raise FjmValueError(f"model {str(given)!r}: a model file, not a derived model; derive it first "
                            f"(`fjm derive --model-file {shlex.quote(str(given))} --out DIR`), then give DIR or "
                            f"DIR/{_model_file_name(path)}")
    elif path.is_file() and path.suffix.lower() == ".urdf":
        raise FjmValueError(f"model {str(given)!r}: a URDF, not a derived model; name it in a model file "
                            "(docs/usage.md#model-files), derive that (`fjm derive --model-file FILE.toml --out "
                            "DIR`), then give DIR/<name>")
    return str(given)
