"""The one registry of every extension point (eelsim.registry): names, errors, plug-ins.

Plug-ins are found through importlib.metadata entry points; here a tiny installed distribution
(a ``*.dist-info`` folder with ``entry_points.txt``) is written into a temporary folder put on
``sys.path``, as pip would install it (the ``install_distribution`` fixture of conftest.py).
"""

import logging
import sys
import types

import pytest

from eelsim.registry import DuplicateNameError, Registry, RegistryError, UnknownNameError


def test_names_descriptions_and_order_are_the_registrations():
    reg = Registry("widget", "eelbot.test_widgets_none")
    first = object()
    assert reg.add("b", first, "the first") is first

    @reg.add("a", "the second")
    def second():
        """Not the description: the registration's line is."""

    assert reg.names() == ("b", "a") and list(reg) == ["b", "a"]
    assert reg["a"] is second and reg.get("zzz") is None and "b" in reg and len(reg) == 2
    assert reg.descriptions() == {"b": "the first", "a": "the second"}


def test_a_description_comes_from_the_object_when_not_given_and_one_is_required():
    reg = Registry("widget", "eelbot.test_widgets_none")

    def documented():
        """Makes widgets.

        More than one line.
        """

    reg.add("doc", documented)
    assert reg.description("doc") == "Makes widgets."
    with pytest.raises(RegistryError, match="widget 'bare': give a one-line description"):
        reg.add("bare", 42)


def test_a_taken_name_is_refused_and_the_same_object_again_is_not():
    reg = Registry("widget", "eelbot.test_widgets_none")
    thing = object()
    reg.add("w", thing, "one")
    reg.add("w", thing, "one")  # a module imported twice
    with pytest.raises(DuplicateNameError, match="a widget named 'w' is already registered"):
        reg.add("w", object(), "another")
    assert reg["w"] is thing


def test_an_unknown_name_is_refused_naming_the_known_ones():
    reg = Registry("widget", "eelbot.test_widgets_none", plural="widgets")
    reg.add("beta", 1, "b")
    reg.add("alpha", 2, "a")
    with pytest.raises(UnknownNameError, match="unknown widget 'gamma'; known widgets: alpha, beta"):
        reg["gamma"]
    with pytest.raises(ValueError):  # an UnknownNameError is a ValueError (and a KeyError)
        reg.entry("gamma")
    assert str(UnknownNameError("plain text")) == "plain text"


def test_the_registrys_check_refuses_an_object_with_its_reason():
    def positive(name, value):
        if value <= 0:
            raise ValueError(f"must be positive, got {value}")

    reg = Registry("gain", "eelbot.test_widgets_none", check=positive)
    with pytest.raises(RegistryError, match="gain 'k': must be positive, got -1"):
        reg.add("k", -1, "a gain")
    assert "k" not in reg


def test_a_normalised_registry_finds_any_spelling():
    reg = Registry("scheme", "eelbot.test_widgets_none", normalise=str.lower)
    reg.add("Serial", 1, "a port")
    assert reg["SERIAL"] == 1 and reg.names() == ("serial",)


def test_plug_ins_register_under_their_entry_point_names_once(tmp_path, monkeypatch,
                                                             install_distribution):
    install_distribution("widget_maker", {"eelbot.test_widgets": {
        "spanner": "widget_maker_mod:SPANNER", "decorated": "widget_maker_mod"}},
        {"widget_maker_mod": (
            "import eelbot_test_registry as r\n"
            "class Spanner:\n    description = 'turns nuts'\n"
            "SPANNER = Spanner()\n"
            "@r.REG.add('decorated', 'registers itself on import')\n"
            "def decorated():\n    pass\n")})
    reg = Registry("widget", "eelbot.test_widgets")
    host = types.ModuleType("eelbot_test_registry")
    host.REG = reg
    monkeypatch.setitem(sys.modules, "eelbot_test_registry", host)
    monkeypatch.syspath_prepend(str(tmp_path))
    reg.add("hammer", 1, "built in")
    names = reg.names()  # plug-ins loaded on the first lookup, after the built-ins
    assert names[0] == "hammer" and set(names) == {"hammer", "spanner", "decorated"}
    assert reg.description("spanner") == "turns nuts"
    assert reg.entry("spanner").origin == "spanner = widget_maker_mod:SPANNER"
    assert reg.entry("decorated").origin == "decorated = widget_maker_mod"
    assert reg.plugin_errors() == [] and reg.load_plugins() == []  # once: no second registration


def test_a_broken_plug_in_is_reported_naming_its_entry_point_and_the_rest_works(
        tmp_path, monkeypatch, caplog, install_distribution):
    install_distribution("broken_widgets", {"eelbot.test_broken": {
        "missing": "no_such_module_anywhere:THING",
        "empty": "broken_widgets_mod",
        "clash": "broken_widgets_mod:OTHER",
        "good": "broken_widgets_mod:GOOD"}},
        {"broken_widgets_mod": "class W:\n    description = 'a widget'\nOTHER, GOOD = W(), W()\n"})
    monkeypatch.syspath_prepend(str(tmp_path))
    reg = Registry("widget", "eelbot.test_broken")
    reg.add("clash", "built-in clash", "built in")
    with caplog.at_level(logging.WARNING, logger="eelsim.registry"):
        assert reg.names() == ("clash", "good")
    problems = {p.entry_point: p.error for p in reg.plugin_errors()}
    assert set(problems) == {"missing = no_such_module_anywhere:THING",
                             "empty = broken_widgets_mod", "clash = broken_widgets_mod:OTHER"}
    assert "ModuleNotFoundError" in problems["missing = no_such_module_anywhere:THING"]
    assert "registers no widget named 'empty'" in problems["empty = broken_widgets_mod"]
    assert "already registered" in problems["clash = broken_widgets_mod:OTHER"]
    assert "plug-in 'missing = no_such_module_anywhere:THING' (eelbot.test_broken) not loaded" \
        in caplog.text
    assert reg["clash"] == "built-in clash"


def test_every_extension_point_is_a_registry_of_its_own_group():
    from eelsim.fluid import FLUID_LAWS
    from eelsim.guidance import GUIDANCE_LAWS
    from eelsim.joints import JOINT_MODELS

    groups = {r.group for r in (FLUID_LAWS, JOINT_MODELS, GUIDANCE_LAWS)}
    assert groups == {"eelbot.fluid_laws", "eelbot.joint_models", None}
    assert {"morison", "galilean_lift"} <= set(FLUID_LAWS) and {"pd", "servo"} <= set(JOINT_MODELS)
    assert GUIDANCE_LAWS.names() == ("pursuit", "ilos", "pursuit_ff")
