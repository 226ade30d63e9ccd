"""Spatial (3-D) serial chains and trees, as read from URDF.

:mod:`~derive.spatial.chain` describes a chain (URDF conventions) and computes its build-time
numbers, :mod:`~derive.spatial.urdf` reads a URDF into that description,
:mod:`~derive.spatial.sym3` holds the three-vector algebra, :mod:`~derive.spatial.spatial` turns a
description into symbolic dynamics (CRBA, RNEA), :mod:`~derive.spatial.spatial_jacobian` adds the
tip Jacobian and :mod:`~derive.spatial.spatial_params` names the inertial, payload and elastic
parameters. Builds on the symbolic core (:mod:`derive.core`).
"""
