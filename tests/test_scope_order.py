"""tests/scope_order.py: `make test` hands out the longest modules first, by the seconds of the
last run (or the committed figures), a module it does not know by its test count."""

from __future__ import annotations

import json
from types import SimpleNamespace

from tests import scope_order


def test_the_longest_known_module_goes_first_an_unknown_one_by_its_test_count() -> None:
    known = {"a.py": [10.0, 10], "b.py": [200.0, 2], "c.py": [30.0, 30]}  # 240 s over 42 tests
    queue = {"a.py": [1] * 10, "b.py": [1] * 2, "c.py": [1] * 30}
    assert scope_order.longest(queue, known) == "b.py"  # not c.py, the one with the most tests
    del queue["b.py"]
    queue["new.py"] = [1] * 7  # 7 tests x (240 / 42) s = 40 s: before c.py's 30 s
    assert scope_order.longest(queue, known) == "new.py"
    queue["new.py"] = [1] * 5  # 28.6 s
    assert scope_order.longest(queue, known) == "c.py"


def test_a_class_is_its_own_unit_as_in_xdist() -> None:
    assert scope_order.scope_of("tests/x/test_a.py::test_b[1-2]") == "tests/x/test_a.py"
    assert scope_order.scope_of("tests/x/test_a.py::TestC::test_d") == "tests/x/test_a.py::TestC"


def test_the_cache_overrides_the_committed_figures_and_bad_entries_are_ignored(tmp_path, monkeypatch) -> None:
    committed = tmp_path / "module_seconds.json"
    committed.write_text(json.dumps({"a.py": [5.0, 3], "b.py": [7.0, 1]}))
    monkeypatch.setattr(scope_order, "COMMITTED", committed)
    cache = {scope_order.CACHE_KEY: {"b.py": [9.5, 2], "c.py": 4.0, "d.py": ["x", 1]}}
    config = SimpleNamespace(cache=SimpleNamespace(get=lambda key, default: cache.get(key, default)))
    assert scope_order.known_seconds(config) == {"a.py": [5.0, 3], "b.py": [9.5, 2]}
    assert scope_order.known_seconds(SimpleNamespace()) == {"a.py": [5.0, 3], "b.py": [7.0, 1]}


def test_the_committed_figures_are_readable() -> None:
    # (to refresh them after a `make test`: cp .pytest_cache/v/hopkinson/module-seconds tests/module_seconds.json)
    known = scope_order.known_seconds(SimpleNamespace())
    assert len(known) > 50 and all(seconds >= 0 and tests >= 0 for seconds, tests in known.values())
