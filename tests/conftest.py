"""Suite-wide test plumbing: one shared set cache, and the slow tests scheduled first.

Neither changes what a test asserts.

* ``shared_set_cache``: the set cache the product itself uses (``$MUVSIM_CACHE_DIR`` or
  ``~/.cache/muvsim``, :func:`controllers.settings.default_cache_dir`).  Fixtures that only need
  synthesised families (not the cache's own behaviour) take their sets from it, so a class is
  synthesised once per run instead of once per fixture and worker (the jerk model alone took
  ~100 s per synthesis on the loaded 2-core machine).  The cache is keyed by model and settings
  and written atomically, so both xdist workers may share it.  Tests *about* the cache
  (``from_cache`` after a first call, corrupt files) keep their own empty ``tmp_path`` caches.
* Slow tests first: ``pytest -n 2`` (xdist ``load``) hands tests out round-robin in collection
  order, then on demand; a 2-minute test collected last leaves one worker idle for 2 minutes at
  the end.  Sorting the known-slow tests (measured with ``--durations``) to the front is the
  longest-processing-time-first rule, so both workers finish together.  Only the order changes.
"""

from __future__ import annotations

import pytest

from controllers.settings import default_cache_dir

#: Test files / node ids measured slowest (``--durations=40``, cold cache, 2 workers), slowest
#: first.  A prefix of a node id; anything not listed keeps its collection order after these.
SLOW_FIRST = (
    "tests/benchmarks/test_quick.py",
    "tests/bridge/test_cosim.py::test_no_footprint_overlap_and_no_invariant_violation",
    "tests/bridge/test_sweep.py",
    "tests/bridge/test_sumo_cosim.py::test_small_grid_every_vehicle_arrives",
    "tests/bridge/test_sumo_claim_cache.py",
    "tests/bridge/test_freeplane.py::test_jerk_model_follows_waypoints",
    "tests/bridge/test_sumo_scenarios.py",
    "tests/bridge/test_sumo_signals.py",
    "tests/bridge/test_stopping.py",
    "tests/bridge/test_crash_outputs.py",
    "tests/bridge/test_canary.py",
    "tests/bridge/test_report_vs_sumo.py",
    "tests/benchmarks/",
    "tests/controllers/test_synthesis.py::test_one_step_property_and_nesting",
    "tests/analysis/test_plots.py::test_a_plot_per_kind",
    "tests/tm/test_manager.py::test_multi_step_random_walk_keeps_the_invariant",
    "tests/tm/test_reach.py::test_random_fleets_on_a_lane_never_touch",
    "tests/bridge/test_cosim.py",
    "tests/bridge/test_sumo_cosim.py",
)


def _rank(nodeid: str) -> int:
    for i, prefix in enumerate(SLOW_FIRST):
        if nodeid.startswith(prefix):
            return i
    return len(SLOW_FIRST)


def pytest_collection_modifyitems(session, config, items):
    """Stable sort: known-slow tests first (same order on every xdist worker, as xdist requires)."""
    items.sort(key=lambda item: _rank(item.nodeid))


@pytest.fixture(scope="session")
def shared_set_cache():
    """The product's set cache directory, shared by all tests and both xdist workers."""
    return default_cache_dir()
