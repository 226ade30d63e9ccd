"""Pieces of model files (TOML) that several tests write."""

#: The body of a ``[spring]`` table: the three-segment law of the harmonic-drive datasheet
#: (stiffness N m/rad, breakpoint torques N m, blend width rad; ``range`` the declared deflection, rad).
THREE_SEGMENT_SPRING = """\
law = "three_segment"
range = 0.01
K_1 = 1.3e4
K_2 = 1.7e4
K_3 = 2.0e4
T_1 = 14.0
T_2 = 48.0
w_blend = 2e-4
"""
