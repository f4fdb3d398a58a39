"""Longest modules first on the xdist workers (`make test`: -n 2 --dist loadscope).

xdist's loadscope hands each worker a whole module (its module fixtures are computed once) in
the order of their test counts. A module with a long fixture and few tests then starts last
and runs alone at the end. Here the controller records each module's seconds (setup, call and
teardown of its tests) in the pytest cache, and the next run hands out the longest remaining
module first (longest-processing-time scheduling: the run ends at most about one module's
time after the ideal, half the total on 2 workers). A module the cache does not know counts
its tests times the mean test's seconds. Only the order changes: what runs, and where each
module's tests run together, is loadscope's.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import pytest

CACHE_KEY = "hopkinson/module-seconds"


def scope_of(nodeid: str) -> str:
    """The loadscope unit of a test: its module, or its class (xdist's own rule)."""
    return nodeid.rsplit("::", 1)[0]


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    cache = getattr(config, "cache", None)  # (none with -p no:cacheprovider)
    if config.getvalue("dist") != "loadscope" or cache is None:
        return None
    from xdist.scheduler import LoadScopeScheduling

    known: dict[str, float] = cache.get(CACHE_KEY, {})
    if not known or not hasattr(LoadScopeScheduling, "_assign_work_unit"):
        return None  # a first run (or another xdist): its own order
    tests_known = cache.get(CACHE_KEY + "-tests", {})
    per_test_s = sum(known.values()) / max(1, sum(tests_known.values()))

    class LongestFirst(LoadScopeScheduling):  # type: ignore[misc, valid-type]
        def _assign_work_unit(self, node: Any) -> None:
            def seconds(scope: str) -> float:
                return known.get(scope, per_test_s * len(self.workqueue[scope]))

            self.workqueue.move_to_end(max(self.workqueue, key=seconds), last=False)
            super()._assign_work_unit(node)

    return LongestFirst(config, log)


class _ModuleSeconds:
    """Sums each module's seconds in the process that runs or controls the tests."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.tests: dict[str, int] = defaultdict(int)

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        scope = scope_of(report.nodeid)
        self.seconds[scope] += report.duration
        self.tests[scope] += report.when == "call"


def pytest_configure(config: pytest.Config) -> None:
    # `make test` runs only: a run of a few tests (-k) would record a module's part as its whole
    if not _is_worker(config) and config.getvalue("dist") == "loadscope":
        config.pluginmanager.register(_ModuleSeconds(), "hopkinson-module-seconds")


def pytest_sessionfinish(session: pytest.Session) -> None:
    config = session.config
    cache = getattr(config, "cache", None)
    recorder = config.pluginmanager.get_plugin("hopkinson-module-seconds")
    if _is_worker(config) or cache is None or not isinstance(recorder, _ModuleSeconds) or not recorder.seconds:
        return
    # the modules run this time replace their old figures; the rest are kept
    cache.set(CACHE_KEY, {**cache.get(CACHE_KEY, {}), **{k: round(v, 2) for k, v in recorder.seconds.items()}})
    cache.set(CACHE_KEY + "-tests", {**cache.get(CACHE_KEY + "-tests", {}), **recorder.tests})
