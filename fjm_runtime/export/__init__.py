"""Exporters of generated models to other tools (MJCF for MuJoCo): text only, no SymPy, no MuJoCo import."""
