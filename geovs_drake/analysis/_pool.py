"""One process pool for the studies that run many scenarios (compare, Monte Carlo,
robustness). Dask stays in the sweep, which needs a cluster's bookkeeping.

Why processes: the Python systems hold the GIL, so threads run one loop at a time.
Why spawn: a fresh interpreter per worker, no forked Drake, Meshcat or numba state.
Why YAML: Drake's bound structs (``SimulatorConfig``) do not pickle; a scenario
travels as the text ``yaml_dump_typed`` writes and ``load_scenario`` reads.
A script that calls these with ``workers > 1`` needs the ``if __name__ ==
"__main__":`` guard; notebooks need nothing.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from pydrake.common.yaml import yaml_dump_typed

from geovs_drake.scenario import ScenarioConfig, load_scenario

__all__ = ["map_scenarios"]

T = TypeVar("T")


def _call(function: Callable[..., T], config_yaml: str, rest: tuple) -> T:
    return function(load_scenario(data=config_yaml), *rest)


def map_scenarios(
    function: Callable[..., T],
    tasks: Sequence[tuple[ScenarioConfig, *tuple[Any, ...]]],
    workers: int = 1,
) -> Iterator[T]:
    """``function(config, *rest)`` for each ``(config, *rest)`` of ``tasks``, in order.

    ``workers <= 1`` runs them in this process; more, in that many spawned
    processes (``function`` must be a module-level function). Results come back in
    the order of ``tasks``, each as soon as it and those before it are done.
    """
    if workers <= 1:
        for config, *rest in tasks:
            yield function(config, *rest)
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [
            pool.submit(_call, function, yaml_dump_typed(config), tuple(rest))
            for config, *rest in tasks
        ]
        for future in futures:
            yield future.result()
