"""Reading a SUMO network's own settings (bridge.sumo_inputs): the turn acceleration its junction
lanes' speeds were built with, from SUMO's shipped networks and from edited copies."""

import gzip

import pytest

from bridge.sumo_inputs import InputError, net_turn_accel
from sumo_nets.sumo_tools import sumo_home

GAME = sumo_home() / "tools" / "game"


def test_shipped_networks_with_and_without_the_attribute():
    assert net_turn_accel(GAME / "cross" / "cross.net.xml") == 5.5      # netconvert's default, recorded
    assert net_turn_accel(GAME / "corridor" / "corridor.net.xml") is None  # written before SUMO 1.2: none


def _copy(tmp_path, name, value, gz=False):
    text = (GAME / "cross" / "cross.net.xml").read_text().replace('limitTurnSpeed="5.50"', value, 1)
    p = tmp_path / name
    if gz:
        with gzip.open(p, "wt") as fh:
            fh.write(text)
    else:
        p.write_text(text)
    return p


def test_edited_values_gzip_and_bad_input(tmp_path):
    assert net_turn_accel(_copy(tmp_path, "a.net.xml", 'limitTurnSpeed="3.25"')) == 3.25
    assert net_turn_accel(_copy(tmp_path, "b.net.xml.gz", 'limitTurnSpeed="4.00"', gz=True)) == 4.0
    assert net_turn_accel(_copy(tmp_path, "c.net.xml", 'limitTurnSpeed="-1.00"')) is None  # not limited
    with pytest.raises(InputError, match=r"d\.net\.xml.*limitTurnSpeed='fast' is not a number"):
        net_turn_accel(_copy(tmp_path, "d.net.xml", 'limitTurnSpeed="fast"'))
    with pytest.raises(InputError, match=r"missing\.net\.xml: cannot be read"):
        net_turn_accel(tmp_path / "missing.net.xml")
    (tmp_path / "e.net.xml").write_text("not xml at all <")
    with pytest.raises(InputError, match=r"e\.net\.xml: not well-formed"):
        net_turn_accel(tmp_path / "e.net.xml")
