"""Longest modules first on the xdist workers (`make test`: -n 3 --dist loadscope).

xdist's loadscope hands each worker a whole module (its module fixtures are computed once) in
the order of their test counts. A module with a long fixture and few tests then starts last
and runs alone at the end. Here the controller of a `make test` run records each module's
seconds (setup, call and teardown of its tests) in the pytest cache, and the next run hands
out the longest remaining module first (longest-processing-time scheduling: the run ends at
most about one module's time after the ideal, half the total on 2 workers). Before a first
run, tests/module_seconds.json (a run of the whole suite, committed) gives the figures. A
module known to neither counts its tests times the mean test's seconds. Only the order
changes: what runs, and where each module's tests run together, is loadscope's.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Mapping, Sized
from pathlib import Path
from typing import Any

import pytest

CACHE_KEY = "hopkinson/module-seconds"  # {module: [seconds, tests]}
COMMITTED = Path(__file__).with_name("module_seconds.json")


def scope_of(nodeid: str) -> str:
    """The loadscope unit of a test: its module, or its class (xdist's own rule)."""
    return nodeid.rsplit("::", 1)[0]


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def known_seconds(config: pytest.Config) -> dict[str, list[float]]:
    """{module: [seconds, tests]}: the committed figures, updated by this checkout's runs."""
    try:
        committed = json.loads(COMMITTED.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        committed = {}
    cache = getattr(config, "cache", None)  # (none with -p no:cacheprovider)
    merged = {**committed, **(cache.get(CACHE_KEY, {}) if cache is not None else {})}
    return {scope: [float(v[0]), int(v[1])] for scope, v in merged.items()
            if isinstance(v, list) and len(v) == 2 and all(isinstance(x, int | float) for x in v)}


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    known = known_seconds(config)
    if not known or not hasattr(LoadScopeScheduling, "_assign_work_unit"):
        return None  # xdist's own order

    class LongestFirst(LoadScopeScheduling):  # type: ignore[misc, valid-type]
        def _assign_work_unit(self, node: Any) -> None:
            self.workqueue.move_to_end(longest(self.workqueue, known), last=False)
            super()._assign_work_unit(node)

    return LongestFirst(config, log)


def longest(workqueue: Mapping[str, Sized], known: Mapping[str, list[float]]) -> str:
    """The module of `workqueue` (module -> its tests) expected to take longest: its seconds in
    `known` ({module: [seconds, tests]}), else its test count times the mean test's seconds."""
    per_test_s = sum(s for s, _ in known.values()) / max(1.0, sum(n for _, n in known.values()))
    return max(workqueue, key=lambda scope: known[scope][0] if scope in known else per_test_s * len(workqueue[scope]))


class _ModuleSeconds:
    """Sums each module's seconds and tests in the process that controls the run."""

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
    ran = {scope: [round(s, 2), recorder.tests[scope]] for scope, s in recorder.seconds.items()}
    cache.set(CACHE_KEY, {**cache.get(CACHE_KEY, {}), **ran})
