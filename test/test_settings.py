"""One settings schema: every PlannerSettings field reaches the node's parameters, the
problem file and the plan command's flags with the same name, range and default."""

import math
from dataclasses import fields

import pytest

from cdh_planner.cli import build_parser
from cdh_planner.errors import InputError
from cdh_planner.parsing.problem import SETTING_KEYS, TOP_KEYS, TOP_SETTINGS, settings_from_dict
from cdh_planner.ros.core.params import SETTING_PARAMETERS, SPEC, check_value
from cdh_planner.fields import BOOL, CHOICE
from cdh_planner.settings import SETTINGS, PlannerSettings, check_setting


def _plan_parser():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sub.choices["plan"]


def _bad_values(kind, s):
    """Values the schema must refuse: outside the range, at an open bound, wrong type."""
    if kind == BOOL:
        return [1, "yes"]
    if kind == CHOICE:
        return ["nonsense", 3]
    out = ["5", math.nan, math.inf]
    if s.low is not None:
        out.append(s.low if s.open_low else s.low - 1)
    if s.high is not None:
        out.append(s.high if s.open_high else s.high * 2)
    return out


@pytest.mark.parametrize("name", list(SETTINGS))
def test_every_setting_reaches_every_edge_alike(name):
    s = SETTINGS[name]
    kind, default = s.kind, s.default
    # the node: a parameter of that name, default, range and choices
    spec = SPEC[s.parameter]
    assert SETTING_PARAMETERS[name] == s.parameter
    assert spec.default == default and (spec.low, spec.high) == (s.low, s.high)
    assert (spec.open_low, spec.open_high, tuple(spec.choices)) == (s.open_low, s.open_high, s.choices)
    # the problem file: a key (beside planner: or in it)
    assert name in (TOP_SETTINGS if s.top_level else SETTING_KEYS)
    assert (name in TOP_KEYS) == s.top_level
    # the CLI: a flag whose default leaves the file's value alone
    action = next(a for a in _plan_parser()._actions if s.flag in a.option_strings)
    assert action.dest == name and action.default is None
    if s.choices:
        assert tuple(action.choices) == s.choices
    # the same refusals everywhere, each naming its own field
    for bad in _bad_values(kind, s):
        with pytest.raises(InputError, match=name):
            check_setting(name, bad)
        with pytest.raises(InputError, match=s.parameter.replace(".", r"\.")):
            check_value(spec, bad)
        if not s.top_level:
            with pytest.raises(InputError, match=f"planner.{name}"):
                settings_from_dict({name: bad}, "planner")
    assert check_setting(name, default) == default


def test_defaults_are_valid_and_fields_all_have_a_schema():
    assert PlannerSettings().check() == PlannerSettings()
    assert {f.name for f in fields(PlannerSettings)} == set(SETTINGS)
    flags = [s.flag for s in SETTINGS.values()]
    params = [s.parameter for s in SETTINGS.values()]
    assert len(set(flags)) == len(flags) and len(set(params)) == len(params)
