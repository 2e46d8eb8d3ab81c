"""One schema: every key vloop/files/schema.py documents (docs/file-format.md's tables are generated from it,
tests/test_docs.py keeps them equal) is accepted by the readers, and a key the schema does not name is refused,
in every section."""

from __future__ import annotations

import copy

import pytest

import vloop
from vloop.files import schema
from vloop.files.fileformat import to_dict

BASE = {
    "name": "base",
    "joints": {"O2": [0.0, 0.0], "O4": [4.0, 0.0], "A": [0.0, 2.0], "B": [4.0, 2.5]},
    "links": {
        "ground": {"joints": ["O2", "O4"], "ground": True},
        "crank": {"joints": ["O2", "A"]},
        "coupler": {"joints": ["A", "B"]},
        "rocker": {"joints": ["O4", "B"]},
    },
    "drivers": [{"link": "crank", "omega": 1.0}],
    "time": {"start": 0.0, "stop": 0.5, "step": 0.1},
}
SLIDER_CRANK = {
    "name": "sc",
    "joints": {"O2": [0.0, 0.0], "A": [0.0, 1.0], "B": [3.0, 0.0]},
    "links": {
        "ground": {"joints": ["O2"], "ground": True},
        "crank": {"joints": ["O2", "A"]},
        "rod": {"joints": ["A", "B"]},
    },
    "sliders": {"blk": {"joint": "B", "guide": "ground", "axis": [1.0, 0.0]}},
    "points": {"P": {"link": "rod", "at": [1.5, 0.5]}},
    "drivers": [{"slider": "blk", "v": -0.1}],
    "time": {"start": 0.0, "stop": 0.5, "step": 0.1},
}


WATT_FROM_DIMENSIONS = {  # the keys only a file written from dimensions takes: a ternary by sides, a slider by angle
    "name": "watt",
    "joints": {"O2": [0.0, 0.0], "O4": [5.0, 0.0], "O6": [12.0, -4.0], "B": [7.0, 3.0], "D": [9.0, -1.0]},
    "links": {
        "ground": {"joints": ["O2", "O4", "O6"], "ground": True},
        "l2": {"joints": ["O2", "A"], "length": 2.0},
        "l3": {"joints": ["A", "B"], "length": 6.0},
        "l4": {"joints": ["O4", "B", "C"], "sides": [4.0, 3.0], "angle": -2.2689280275926285},
        "l5": {"joints": ["C", "D"], "length": 4.0},
        "l6": {"joints": ["O6", "D"], "length": 4.0},
    },
    "drivers": [{"link": "l2", "theta0": 0.5235987755982988, "omega": 2.0}],
    "time": {"start": 0.0, "stop": 0.5, "step": 0.1},
}
SLIDER_CRANK_FROM_DIMENSIONS = {
    "name": "scd",
    "joints": {"O2": [0.0, 0.0], "B": [3.0, 0.5]},
    "links": {
        "ground": {"joints": ["O2"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": 1.0},
        "rod": {"joints": ["A", "B"], "length": 3.0},
    },
    "sliders": {"blk": {"joint": "B", "guide": "ground", "angle": 0.0, "offset": 0.5}},
    "drivers": [{"link": "crank", "theta0": 1.0, "omega": 1.0}],
    "time": {"start": 0.0, "stop": 0.5, "step": 0.1},
}


def _where(section: str, key: str = "") -> tuple[dict, list]:
    """A valid file and the path of the table that holds the section's keys (``key``: the keys only a file written
    from dimensions takes have one of those)."""
    if (section, key) in (("links", "sides"), ("links", "angle")):
        return copy.deepcopy(WATT_FROM_DIMENSIONS), ["links", "l4"]
    if (section, key) in (("sliders", "angle"), ("sliders", "offset")):
        return copy.deepcopy(SLIDER_CRANK_FROM_DIMENSIONS), ["sliders", "blk"]
    if (section, key) == ("points", "local"):  # instead of 'at'
        data = copy.deepcopy(SLIDER_CRANK)
        del data["points"]["P"]["at"]
        return data, ["points", "P"]
    if section in ("file",):
        return copy.deepcopy(BASE), []
    if section == "links":
        return copy.deepcopy(BASE), ["links", "coupler"]
    if section in ("sliders", "points", "actuator"):
        data = copy.deepcopy(SLIDER_CRANK)
        return data, {"sliders": ["sliders", "blk"], "points": ["points", "P"], "actuator": ["drivers", 0]}[section]
    if section == "crank":
        return copy.deepcopy(BASE), ["drivers", 0]
    if section in ("time", "solver"):
        data = copy.deepcopy(BASE)
        data.setdefault(section, {})
        return data, [section]
    if section == "loads":
        data = copy.deepcopy(BASE)
        data["loads"] = [{"link": "rocker", "torque": 1.0}]
        return data, ["loads", 0]
    if section in ("dynamics", "springs"):
        data = copy.deepcopy(BASE)
        data["links"]["coupler"]["mass"] = 1.0
        data["dynamics"] = {"stop": 1.0, "step": 0.1, "springs": [{"joint": "O4", "k": 1.0}]}
        return data, ["dynamics"] if section == "dynamics" else ["dynamics", "springs", 0]
    raise AssertionError(section)


def _table(data: dict, path: list) -> dict:
    t = data
    for p in path:
        t = t[p]
    return t


@pytest.mark.parametrize(
    ("section", "key"),
    [(s.name, k) for s in schema.SECTIONS if s.name != "joints" for k in s.keys if k.example is not None],
    ids=lambda v: v if isinstance(v, str) else v.name,
)
def test_every_documented_key_with_an_example_is_accepted(section, key):
    data, path = _where(section, key.name)
    _table(data, path)[key.name] = copy.deepcopy(key.example)
    if section == "time" and key.name == "times":
        _table(data, path).clear()
        _table(data, path)["times"] = key.example
    mech = vloop.from_dict(data)
    assert vloop.dumps(vloop.from_dict(to_dict(mech))) == vloop.dumps(mech)  # and it survives the round trip


@pytest.mark.parametrize("section", [s.name for s in schema.SECTIONS if s.name != "joints"])
def test_a_key_the_schema_does_not_name_is_refused(section):
    data, path = _where(section)
    _table(data, path)["colour"] = "red"
    with pytest.raises(vloop.MechanismError, match="unknown key 'colour'"):
        vloop.from_dict(data)


def test_every_key_is_read_somewhere():
    """Each schema key is accepted by its reader: the allowed set the readers check is the schema's."""
    for s in schema.SECTIONS:
        if s.name == "joints":
            continue
        data, path = _where(s.name)
        table = _table(data, path)
        for k in s.keys:
            if k.name not in table:
                table[k.name] = object()  # a wrong value: the message must be about the value, not the key
            try:
                vloop.from_dict(data)
            except vloop.MechanismError as exc:
                assert f"unknown key '{k.name}'" not in str(exc), (s.name, k.name)
            except Exception as exc:  # pragma: no cover - a traceback is a bug
                raise AssertionError(f"{s.name}.{k.name}: {type(exc).__name__}: {exc}") from None
            data, path = _where(s.name)
            table = _table(data, path)
