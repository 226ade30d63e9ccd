"""Identification of the drives (stiffness, rotor inertia, damping, friction) from a robot log."""
