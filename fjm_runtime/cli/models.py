"""``fjm models``: every model the runtime can load, with its size and where it comes from."""
from __future__ import annotations

import json


#: The help of every command's model argument: a built-in name or the path of a derived model.
MODEL_HELP = ("a built-in model name (see `fjm models`), or the path of a derived model: the directory "
              "`fjm derive --model-file FILE --out DIR` wrote (DIR or DIR/<name>)")


def add_arguments(p) -> None:
    """The arguments of ``fjm models`` on its parser ``p`` (name, help, description: commands.toml)."""
    p.add_argument("--json", action="store_true", help="one JSON list instead of a table")


def model_rows():
    """One dict per model: ``name``, ``n``, ``parameters`` (count), ``source`` (str)."""
    from .. import available_models, load
    rows = []
    for name in available_models():
        m = load(name)
        rows.append({"name": name, "n": int(m.n), "parameters": len(m.param_names), "source": describe_source(m)})
    return rows


def describe_source(m) -> str:
    """``'built-in'``, ``'URDF <path>'`` or ``'FJM_GENERATED <dir>'`` (plus the URDF for derived arms)."""
    import os
    from pathlib import Path
    directory = getattr(m, "directory", None) or getattr(m, "path", None)
    manifest = getattr(m, "manifest", None) or {}
    src = manifest.get("source") if isinstance(manifest, dict) else None
    urdf = src.get("urdf") or src.get("path") if isinstance(src, dict) else None
    env = os.environ.get("FJM_GENERATED")
    where = "built-in"
    if env and directory is not None and Path(env).resolve() in Path(directory).resolve().parents:
        where = f"FJM_GENERATED {env}"
    if urdf:
        return f"URDF {urdf}" if where == "built-in" else f"{where} (URDF {urdf})"
    return where


def run(args) -> int:
    """Print the model list."""
    rows = model_rows()
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    width = max([len(r["name"]) for r in rows] + [5])
    print(f"{'model':<{width}}  {'n':>2}  {'params':>6}  source")
    for r in rows:
        print(f"{r['name']:<{width}}  {r['n']:>2}  {r['parameters']:>6}  {r['source']}")
    return 0
