"""The planar chains: ``link1`` and ``planar<n>`` (and their complete-model variants) in closed form.

:mod:`~derive.planar.planar` states the rigid-body dynamics of a planar serial chain of revolute
joints directly (no URDF, no recursive algorithm) on top of the symbolic core (:mod:`derive.core`).
"""
