"""Movement-authority families (design.md §7): N_L, the paper mode untouched, the cache key,
and the safe-side tables g_m, h_m.

Tolerances: membership MEMBERSHIP_TOL (1e-9) as everywhere; the tables are compared with the
exact polygon values with no slack beyond AUTHORITY_TABLE_TOL, which they add on the safe side.
"""

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from controllers import tolerances as tol
from controllers.authority import _ccw, _g_fast, _h_fast, build_tables, g_exact, h_exact
from controllers.classes import builtin_classes, get_class
from controllers.settings import SettingsError, SynthesisSettings
from controllers.synthesis import SynthesisError, _cache_path, along_factor, synthesize

URBAN = ("car", "bus", "truck")


@pytest.fixture(scope="module")
def cache(shared_set_cache):
    return shared_set_cache


@pytest.fixture(scope="module")
def ma(cache):
    """Movement-authority family and tables per urban class."""
    out = {}
    for c in URBAN:
        vc = get_class(c)
        fam = synthesize(vc.model, SynthesisSettings(authority_decel=vc.comfort_decel, cache_dir=cache))
        out[c] = (vc, fam, build_tables(fam))
    return out


def _ma_state(vc, fam, level):
    """(-s_MA, v̄) in the along factor of ``fam``, tested against its ``level``."""
    f = fam.factors[along_factor(fam)]
    e = np.zeros(len(f.states))
    e[list(f.states).index(0)] = -fam.authority.s_ma
    e[list(f.states).index(2)] = vc.v_max
    return bool(f.levels[level].contains(e[None], tol.MEMBERSHIP_TOL)[0])


@pytest.mark.parametrize("c", URBAN)
def test_n_l_is_the_first_level_holding_full_speed_a_braking_distance_before(ma, c, cache):
    vc, fam, _ = ma[c]
    a = fam.authority
    assert a.s_ma == pytest.approx(vc.v_max ** 2 / (2 * vc.comfort_decel) + 2 * vc.model.delta, abs=1e-12)
    assert _ma_state(vc, fam, fam.N) and not _ma_state(vc, fam, fam.N - 1)
    # the paper's N (first level meeting condition (8)) is kept as n_min and is below N_L
    paper = synthesize(vc.model, SynthesisSettings(cache_dir=cache))
    assert a.n_min == paper.N < fam.N
    # every factor has the same number of levels, nested (T^{l-1} ⊆ T^l)
    for f in fam.factors:
        assert len(f.levels) == fam.N + 1
        for l in (1, a.n_min, fam.N):
            assert f.levels[l - 1] <= f.levels[l]


def test_paper_n_table_and_cache_key_unchanged(shared_set_cache):
    """The paper mode (authority_decel None) keeps the N table of benchmarks/results/controllers.csv
    (measured before this mode existed) and the cache key format, so old caches stay valid."""
    table = {"paper-a": 22, "paper-b": 28, "paper-c": 20, "paper-d": 22, "car": 22, "bus": 31, "truck": 31}
    s = SynthesisSettings(cache_dir=shared_set_cache)
    for name, vc in builtin_classes().items():
        assert synthesize(vc.model, s).N == table[name], name
    assert s.key() == "q1-r1-e0.05-L200-Tauto-auto-x0"


def test_cache_key_includes_the_deceleration(tmp_path):
    m = get_class("car").model
    keys = {_cache_path(m, SynthesisSettings(authority_decel=a, cache_dir=tmp_path)) for a in (None, 2.0, 2.5)}
    assert len(keys) == 3
    s = SynthesisSettings(authority_decel=2.0, cache_dir=tmp_path)
    first = synthesize(m, s)
    second = synthesize(m, s)
    assert second.from_cache and not first.from_cache
    assert second.N == first.N and second.authority == first.authority
    assert first.summary()["N_min"] == first.authority.n_min


def test_bad_deceleration_is_named():
    with pytest.raises(SettingsError, match="authority_decel"):
        SynthesisSettings(authority_decel=-1.0)
    with pytest.raises(SynthesisError, match="authority_decel = 3 m/s\\^2 must be below"):
        synthesize(get_class("car").model, SynthesisSettings(authority_decel=3.0, cache=False))
    with pytest.raises(SynthesisError, match="max_levels=30"):
        synthesize(get_class("car").model, SynthesisSettings(authority_decel=2.5, max_levels=30, cache=False))


@pytest.mark.parametrize("c", URBAN)
@hsettings(max_examples=60, deadline=None)
@given(data=st.data())
def test_tables_bound_every_state_of_the_level(ma, c, data):
    """For a random state (p, v) of T^m and any w <= v: p <= g(m, w); any w >= v: p >= h(m, w)."""
    vc, fam, T = ma[c]
    f = fam.factors[along_factor(fam)]
    m = data.draw(st.integers(0, fam.N))
    seed = data.draw(st.integers(0, 2 ** 31))
    rng = np.random.default_rng(seed)
    V = f.levels[m].vertices
    W = rng.dirichlet(np.full(len(V), 0.2), size=40)
    pts = W @ V
    ip, iv = list(f.states).index(0), list(f.states).index(2)
    p, v = pts[:, ip], pts[:, iv]
    below = v - rng.random(len(v)) * data.draw(st.sampled_from([0.0, 0.005, 0.5, 30.0]))
    above = v + rng.random(len(v)) * data.draw(st.sampled_from([0.0, 0.005, 0.5, 30.0]))
    mm = np.full(len(v), m)
    assert np.all(p <= T.g(mm, below))
    assert np.all(p >= T.h(mm, above))


@pytest.mark.parametrize("c", ["car"])
def test_table_lookup_is_on_the_safe_side_of_the_exact_values(ma, c):
    """Off-grid lookups are >= g_exact and <= h_exact, and at most one grid step away
    (boundary slope |dp/dv| <= 20 s for these sets: 0.2 m at dv = 0.01)."""
    vc, fam, T = ma[c]
    f = fam.factors[along_factor(fam)]
    rng = np.random.default_rng(3)
    for m in (0, 1, fam.authority.n_min, fam.N):
        P = f.levels[m].vertices[:, [list(f.states).index(0), list(f.states).index(2)]]
        w = rng.uniform(P[:, 1].min(), P[:, 1].max(), 500)
        ge, he = g_exact(P, w), h_exact(P, w)
        gt, ht = T.g(np.full(500, m), w), T.h(np.full(500, m), w)
        assert np.all(gt >= ge) and np.all(ht <= he)
        assert np.all(gt - ge <= 0.2) and np.all(he - ht <= 0.2)


@pytest.mark.parametrize("c", URBAN)
def test_boundary_chain_tables_equal_the_vertex_definition(ma, c):
    """The tables are built from the polygon's right / left boundary (O(W log k) a level); they equal
    the definition over every vertex and edge crossing (g_exact, h_exact) at every level, inside and
    outside the velocity range (±inf alike), to 1e-9 m (measured 1.4e-14: interpolation round-off)."""
    vc, fam, _ = ma[c]
    f = fam.factors[along_factor(fam)]
    rng = np.random.default_rng(0)
    for lev in f.levels:
        V = _ccw(lev.vertices[:, [list(f.states).index(0), list(f.states).index(2)]])
        V = np.roll(V, rng.integers(len(V)), axis=0)  # any starting vertex
        w = np.linspace(V[:, 1].min() - 0.3, V[:, 1].max() + 0.3, 801)
        for fast, exact in ((_g_fast, g_exact), (_h_fast, h_exact)):
            a, b = exact(V, w), fast(V, w)
            assert np.array_equal(np.isfinite(a), np.isfinite(b))
            assert np.all(np.abs(a[np.isfinite(a)] - b[np.isfinite(b)]) < 1e-9)
