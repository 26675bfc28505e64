"""Junction zones a route only passes by (SUMO's ``A10KW``, its network unchanged).

The two carriageways of SUMO's ``tools/game/A10KW`` motorway run side by side through the on-ramp
merges ``32500343`` (west-bound) and ``21432413`` (east-bound), each a zone of the junction layer.
A zone's guard is a box around its junction, and it reaches the lanes of the opposite carriageway:
before, a vehicle there asked for the merge's token, waited for it and held it, though its route
never enters the junction (A10KW, 180 s, diagnostic run at 271b749: at 150 s half the waiters of
both merges and a third of their holders were such passers-by; 35 of 601 arrived).  Now a route
needs the tokens of the junctions on its edges only (:meth:`bridge.waypoints.NetGeometry.route_junctions`,
``through`` of :class:`tm.junctions.JunctionGate`).

Both merges add the ramp's lane beside the motorway's (no foes in SUMO's right-of-way matrix), and such
junctions are no zones any more (:func:`bridge.sumo_world.junction_zones`); the run below makes every
junction a zone again, to test ``through`` where it was found.
"""

from pathlib import Path
from types import SimpleNamespace

from bridge import sumo_world
from bridge.sumo_world import junction_zones, run_sumo
from bridge.waypoints import load_net
from sumo_nets.sumo_tools import sumo_home

EAST = "264306385 264308375 264308383 4054057 264308376"  # through 21432413, beside 32500343
WEST = "290296351 240042212 151495040 264308374 399250313 264308373"  # through 32500343, beside 21432413


def _net() -> Path:
    return sumo_home() / "tools" / "game" / "A10KW" / "osm.net.xml"


def test_a_route_passes_through_the_junctions_of_its_edges_only():
    geo = load_net(_net())
    east, west = geo.route_junctions(EAST.split()), geo.route_junctions(WEST.split())
    assert "21432413" in east and "32500343" not in east
    assert "32500343" in west and "21432413" not in west
    assert geo.route_junctions(["264308383"]) == {"34160979", "21432413"}  # where it starts and ends


class _Tokens:
    """Every (zone name, vehicle) that held a token, and the gate."""

    def __init__(self):
        self.held = set()
        self.gate = None
        self.route = None

    def on_step(self, sim, state, decision, row):
        self.gate = sim.junctions
        self.held |= {(sim.junctions.zones[z].name, v) for z, hs in enumerate(sim.junctions.holders) for v in hs}
        fleet = sim.filters._junction_fleet
        if self.route is None and fleet is not None and "e" in fleet.ids:  # its waypoints, as the gate sees them
            row = fleet.ids.index("e")
            self.route = fleet.route(row)[:2] + (fleet.family[row],)


def test_an_east_bound_car_needs_no_token_of_the_west_bound_merge_beside_it(tmp_path, monkeypatch):
    """A lone car on the east-bound carriageway's inner lane (``departPos="last"``, ``departSpeed="max"``, as the
    demo's): its route's hold boxes reach the guard of the west-bound merge ``32500343`` (its waypoints
    meet the guard without ``through``), yet it never holds that token; it holds ``21432413``'s, the
    merge on its own carriageway (within 60 s; 0 SUMO collisions)."""
    net = _net()
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vehicle id="e" depart="0" departLane="2" departPos="last" departSpeed="max">'
        f'<route edges="{EAST}"/></vehicle></routes>')
    cfg = tmp_path / "s.sumocfg"
    cfg.write_text(f'<configuration><input><net-file value="{net}"/><route-files value="r.rou.xml"/></input>'
                   '</configuration>')
    opts = SimpleNamespace(seed=1, duration=60.0, tm="optimal", check="timed", switching="early",
                           disturbance="random", solver="exact", baseline=None, gui=False, quiet=True,
                           controller="authority")
    rec = _Tokens()
    assert not {"21432413", "32500343"} & {zz.name for zz in junction_zones(net)}  # no foes: no zones
    monkeypatch.setattr(sumo_world, "_conflict_free", lambda junction: False)  # every junction a zone, as before
    s = run_sumo(str(cfg), tmp_path / "m", opts, observers_extra=[rec])
    assert s["complete"] and s["safe"], s.get("error") or s["safety_violations"]
    assert s["collisions_sumo"] == 0
    gate = rec.gate
    z = [zz.name for zz in gate.zones].index("32500343")
    _, zs = gate.spans.guard_hits(*rec.route)  # every zone its route reaches (no ``through``): 32500343 among them
    assert z in zs.tolist()
    assert ("21432413", "e") in rec.held and ("32500343", "e") not in rec.held
    assert {zz.name for zz in junction_zones(net)} >= {"21432413", "32500343"}
