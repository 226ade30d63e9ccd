"""The settings of a gain search (:func:`fjm_runtime.analysis.search.search.design`), with their defaults."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

__all__ = ["SearchSettings"]


@dataclass(frozen=True)
class SearchSettings:
    """What :func:`~fjm_runtime.analysis.search.search.design` searches and how (``fjm design``'s flags).

    Attributes
    ----------
    kind : str
        The law (the search covers ``'ismc'``).
    sensing : {'state', 'torque'}
    rate : float
        Control rate, Hz.
    delay : int
        Computation delay, samples.
    sensor : SensorModel, optional
        Default ``SensorModel.panda_white(seed=seed)``.
    interface : CommandInterface, optional
        The command interface (default motor).
    draws : int
        Plant draws of the final check.
    duration : float
        Final run length, s.
    seed : int
        Draws and noise seed.
    u_max : float or sequence of float, optional
        Torque limits, N m (default: the model's efforts).
    screen_draws : int
        Plant draws of the search stages (the first are the box's corners).
    screen_duration : float
        Run length of the search stages, s.
    rounds : int
        Rounds of the pattern search.
    max_extra_delay : int
        Largest extra delay the delay margin tries, samples.
    threads : int, optional
        OpenMP threads (default all cores).
    simd : bool
        The SIMD batch (else the scalar one).
    predict : bool
        Every loop runs with the sample step's delay compensation.
    reference, x0, task : optional
        The task shared by all runs (default: a 0.5 rad sine about q = 0 from rest); ``task`` describes
        it in the gains file.
    active_sets : int
        Active-set passes after the final check.
    thresholds : Thresholds, optional
        What the gains must meet (default :class:`~fjm_runtime.analysis.search.thresholds.Thresholds`).
    spread : PlantSpread, optional
        The nominal parameters and the draws (default ``default_spread(model)``).
    recheck_draws : int, optional
        Fresh draws of the re-check (default ``draws``; 0: none).
    scheduler : optional
        Where the Monte Carlo stages run (None: this process; an address or a ``dask.distributed.Client``).
    screen : optional
        None, ``'linear'`` (the linear sampled-data analysis) or a
        :class:`~fjm_runtime.analysis.search.screen.Screen`: rejects candidates first.
    compare_only : bool
        The law is only compared with one that already met (``--law auto``): at most ``COMPARED_ROUNDS``
        (1) pattern-search rounds, no active-set pass, and when it misses, no margins and no attribution
        (its record is then only a row of the comparison).
    """

    kind: str = "ismc"
    sensing: str = "torque"
    rate: float = 1000.0
    delay: int = 1
    sensor: Any = None
    interface: Any = None
    draws: int = 200
    duration: float = 10.0
    seed: int = 0
    u_max: Any = None
    screen_draws: int = 12
    screen_duration: float = 2.0
    rounds: int = 6
    max_extra_delay: int = 3
    threads: Optional[int] = None
    simd: bool = True
    predict: bool = False
    reference: Any = None
    x0: Any = None
    task: Optional[dict] = None
    active_sets: int = 1
    thresholds: Any = None
    spread: Any = None
    recheck_draws: Optional[int] = None
    scheduler: Any = None
    screen: Any = None
    compare_only: bool = False
