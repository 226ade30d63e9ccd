"""The symbolic core of the derivation: the model and what is derived from it, for any chain.

:mod:`~derive.core.model_base` (the flexible-joint model, its parameters and state symbols),
:mod:`~derive.core.program` (straight-line programmes of named intermediates),
:mod:`~derive.core.rotors` (motor rotors carried by the links), :mod:`~derive.core.lie` (Lie
derivatives and brackets), :mod:`~derive.core.linearize` (the feedback linearization),
:mod:`~derive.core.torque` (its torque-sensing coordinates) and :mod:`~derive.core.spring`
(nonlinear joint springs). The chain builders (:mod:`derive.planar`, :mod:`derive.spatial`) build on
it; nothing here imports them. Pure math: no I/O.
"""
