"""``fjm export mjcf MODEL --out FILE``: write a MuJoCo model (MJCF) of a generated model."""
from __future__ import annotations

from pathlib import Path

from .models import MODEL_HELP
from ..drives import linear_stiffness_indices
from ..export.mjcf import is_complete, write_mjcf
from ..validation import FjmValueError
from .ranges import Range
from .common import check_output_file, parse_assignments


def add_arguments(ex) -> None:
    """The arguments of ``fjm export`` on its parser ``ex`` (name, help, description: commands.toml)."""
    ex.add_argument("format", choices=("mjcf", "controller"),
                    help="output format (mjcf: MuJoCo XML; controller: the designed sampled controller as a C99 "
                         "library directory, needs --gains)")
    ex.add_argument("model", help=MODEL_HELP)
    ex.add_argument("--out", type=Path, required=True,
                    help="output file, e.g. panda.xml (its directory must exist); controller: a directory")
    ex.add_argument("--gains", type=Path, default=None,
                    help="controller: a design file (`fjm design` output, e.g. "
                         "fjm_runtime/control/designed/panda_ismc_tau_1000hz_d1.json)")
    ex.add_argument("--params", type=Path, default=None, metavar="FILE",
                    help="controller: parameter file (TOML [parameters], e.g. from `fjm identify`): the law's "
                         "nominal values (over the design file's params.nominal)")
    ex.add_argument("--substeps", type=float, default=None,
                    help="controller: RK4 substeps of the predictor per sample, an integer 1..1000 (default: the "
                         "substeps rule); only for a design that predicts")
    ex.add_argument("--name", default=None, help="controller: C prefix (default <model>_<kind>[_tau])")
    ex.add_argument("--unverified", action="store_true",
                    help="controller: export a design that records \"meets\": false (refused otherwise), labelled "
                         "unverified in its README and header")
    ex.add_argument("--complete", action="store_true",
                    help="the complete model (rotor i on link i-1, spin coupling; gear ratios N1..Nn from "
                         "<model>_complete): needs a generated <model>_complete")
    ex.add_argument("--K", type=float, default=None,
                    help="joint stiffness, 0 < K <= 1e12 N m/rad (link1: K; others: every K_i)")
    ex.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="parameter value (repeatable) in its domain and 0 or 1e-12..1e12 in magnitude, e.g. --param "
                         "Jm7=0.2 --param m_load=1.5 --param N7=300")
    ex.add_argument("--gear-ratio", type=GEAR_RATIO, default=None,
                    help=f"reduced model: rotor angle = GEAR_RATIO * q_m for every joint, {GEAR_RATIO} (default 1; complete "
                         "models take N1..Nn via --param)")
    ex.add_argument("--timestep", type=float, default=None, help=f"MuJoCo step, {TIMESTEP} (integrator RK4; default 1e-4)")
    ex.add_argument("--interface", default=None, metavar="NAME|FILE.toml",
                    help="controller: what the library's output commands (default: the design's, else motor; "
                         "joint_torque, franka: the library outputs tau_d, the robot filters it and adds gravity)")


#: Gear ratios of a drive (harmonic drives reach 160, stacked gearboxes a few thousand).
GEAR_RATIO = Range(0, 1e4, "", "N", lo_open=True)
#: MuJoCo RK4 step, s: above 10 ms RK4 leaves its stability region on the elastic modes (|omega h| <= 2.8;
#: the Panda's wrist mode is ~700 rad/s); below 0.1 us a second of simulation takes 1e7 steps.
TIMESTEP = Range(1e-7, 1e-2, "s", "timestep", why="MuJoCo's RK4 step; default 1e-4")

#: The flags each format reads; any other given flag is refused (not silently ignored).
_FLAGS = {"controller": ("gains", "params", "substeps", "name", "unverified", "interface"),
          "mjcf": ("complete", "K", "param", "gear_ratio", "timestep")}
_UNSET = {"gains": None, "params": None, "substeps": None, "name": None, "unverified": False, "interface": None,
          "complete": False,
          "K": None, "param": [], "gear_ratio": None, "timestep": None}


def _refuse_foreign_flags(args) -> None:
    """One line for the first flag given that ``args.format`` does not read."""
    for dest, unset in _UNSET.items():
        value = getattr(args, dest)
        if dest not in _FLAGS[args.format] and value != unset:
            flag = "--" + dest.replace("_", "-")
            shown = "" if isinstance(value, bool) else " " + (
                " ".join(value) if isinstance(value, list) else f"{value:g}" if isinstance(value, float) else str(value))
            other = next(f for f, dests in _FLAGS.items() if dest in dests)
            hint = (" (its nominal parameters come from --params FILE or the design's params.nominal)"
                    if dest in ("K", "param") else "")
            raise FjmValueError(f"{flag}{shown}: export {args.format} does not use it{hint}; expected it only with "
                                f"export {other}")


def _model(args):
    from .. import load, available_models
    name = args.model
    if args.complete and not name.endswith("_complete"):
        if f"{name}_complete" not in available_models():
            raise FjmValueError(f"--complete: no complete model {name}_complete (expected one of "
                                f"{', '.join(m for m in available_models() if m.endswith('_complete')) or 'none'})")
        name = f"{name}_complete"
    m = load(name)
    if args.complete and not is_complete(m):
        raise FjmValueError(f"--complete: model {name} is not a complete model")
    return m


def _run_controller(args) -> int:
    """``fjm export controller MODEL --gains FILE --out DIR``."""
    import dataclasses
    from .. import load
    from ..control.design import Design
    from ..export.controller import design_controller, export_controller
    from ..sim.interface import interface_from_spec
    if args.gains is None:
        raise FjmValueError("export controller: --gains FILE is required (a design file from `fjm design`)")
    gains = Design.load(args.gains)
    m = load(args.model)
    if gains.model not in (None, m.name):
        raise FjmValueError(f"--gains {args.gains}: designed for model {gains.model!r}, not {m.name!r}")
    gains = dataclasses.replace(gains, file=gains.file or str(args.gains))
    if args.interface is not None:
        interface_from_spec(args.interface, what="--interface")            # checked before any work
        gains = dataclasses.replace(gains, interface=args.interface)
    from ..export.controller_checks import check_c_values
    from .simulate import params_file_nominal
    design_nominal, file_nominal = gains.nominal(m), params_file_nominal(args.params, m)
    check_c_values(design_nominal, design_nominal.values(), f"--gains {args.gains}: params.nominal.")
    check_c_values(file_nominal, file_nominal.values(), f"--params {args.params}: [parameters] ")
    nominal = {**design_nominal, **file_nominal}
    design = design_controller(m, gains, nominal=nominal or None, substeps=args.substeps, name=args.name,
                               unverified=args.unverified)
    files = export_controller(design, args.out)
    print(f"wrote {len(files)} files to {args.out} ({design.name}: {m.name}, {design.controller.law_kind}, "
          f"{1.0 / design.layout.T:g} Hz, delay {design.layout.delay}, {design.layout.predictor_substeps} substeps); "
          f"build with `make -C {args.out}`{'; UNVERIFIED design (meets: false)' if gains.meets is False else ''}")
    return 0


def _check_mjcf_flags(args) -> None:
    """``--timestep`` within :data:`TIMESTEP` and ``--K`` a stiffness the export holds, in one line each (after
    :func:`_refuse_foreign_flags`, hence not argparse types)."""
    from ..export.controller_checks import check_c_values
    if args.timestep is not None:
        TIMESTEP.check("--timestep", args.timestep)
    if args.K is not None:
        check_c_values(["--K"], [args.K], "")


def run(args) -> int:
    """Run ``fjm export``; returns the exit status."""
    _refuse_foreign_flags(args)
    if args.format == "controller":
        return _run_controller(args)
    check_output_file(args.out, "--out")
    _check_mjcf_flags(args)
    m = _model(args)
    params = parse_assignments(args.param, "--param")
    from ..export.controller_checks import check_c_values
    check_c_values(params, params.values(), "--param ")
    if args.K is not None:
        for i in linear_stiffness_indices(m, "--K"):
            params.setdefault(m.param_names[i], args.K)
    m.params_array(params, arg="--param")  # unknown names and bad values: one line naming --param
    complete = is_complete(m)
    if complete and args.gear_ratio is not None:
        raise FjmValueError(f"--gear-ratio: model {m.name} takes its gear ratios as parameters N1..N{m.n} "
                            "(e.g. --param N1=100)")
    write_mjcf(m, args.out, params, complete=complete, gear_ratio=args.gear_ratio,
               timestep=1e-4 if args.timestep is None else args.timestep)
    print(f"wrote {args.out} (model {m.name}, {'complete' if complete else 'reduced'}, {m.n} joints; "
          "load it with mujoco.MjModel.from_xml_path)")
    return 0
