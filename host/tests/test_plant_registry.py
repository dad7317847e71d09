"""The test plants are a registry: a lab's own tank, registered from its own package through the
``eelbot.plants`` entry points, is offered by ``eelbot dataset`` and ``estimate-bench`` and
records a dataset; an unknown plant is refused naming the known ones (issue 30).

The package is installed as pip would (conftest.py's ``install_distribution`` fixture): a
``*.dist-info`` folder with ``entry_points.txt`` and the module beside it, on ``sys.path``.
"""

import sys

import numpy as np
import pytest
from test_plugins import help_of

from eelhost import cli
from eelhost.data import virtual_tank
from eelhost.data.experiments import load_dataset
from eelhost.data.plants import PLANTS, Plant, register_plant
from eelhost.data.virtual_tank import TABLE3, TankSettings
from eelsim.registry import DuplicateNameError, RegistryError
from eelsim.robot import load_robot

LAB = '''
"""A lab's tank: its water is murky, so its camera's median is centred; its pump leaves a current."""
from eelhost.data.plants import Plant
from eelhost.data.virtual_tank import TABLE3, TankSettings
from eelsim.robot import load_robot

MURKY = Plant("murky", "the lab's tank: centred median and a 3 mm/s current towards 30 deg",
              TankSettings(median="centred", stray_current_m_s=0.003,
                           stray_current_direction_deg=30.0))
MISNAMED = Plant("clear", "says another name than its entry point's", TankSettings())
'''


@pytest.fixture
def lab(tmp_path, monkeypatch, install_distribution, registries_afresh):
    """The lab's package installed; the plant registry loads plug-ins afresh."""
    install_distribution("lab", {"eelbot.plants": {"murky": "lab_plants:MURKY",
                                                   "cloudy": "lab_plants:MISNAMED"}},
                         {"lab_plants": LAB})
    registries_afresh(PLANTS)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("lab_plants", None)


def choices_of(text, option):
    """The {a,b,...} choices argparse prints after ``option`` in a help text."""
    after = text.split(option + " {", 1)[1]
    return set(after.split("}", 1)[0].split(","))


def test_a_labs_plant_is_offered_by_dataset_and_estimate_bench(lab, capsys):
    dataset = help_of(capsys, "dataset")
    assert "murky" in choices_of(dataset, "--plant")
    assert "centred median and a 3 mm/s current" in " ".join(dataset.split())
    bench = " ".join(help_of(capsys, "estimate-bench").split())
    assert "murky" in bench.split("--tanks NAME,...")[-1].split("--coverage")[0]
    assert "murky: the lab's tank" in bench.split("--bands PLANT,...")[-1]
    # the entry point's name is the plant's: one that says another name is refused, named
    assert "cloudy" not in PLANTS
    assert any("cloudy = lab_plants:MISNAMED" in str(e) and "'clear'" in str(e)
               for e in PLANTS.plugin_errors())


@pytest.mark.slow
def test_a_labs_plant_records_a_dataset_with_its_physics(lab, tmp_path, monkeypatch, capsys):
    # the paper's plan cut to one training and one test gait per motion and the two paths, each
    # 1 s long: the plant is what is tested, not the plan
    plan, kept = virtual_tank.paper_experiment_plan(), set()
    short = []
    for motion, split, s in plan:
        if (motion, split) not in kept or motion == "path":
            kept.add((motion, split))
            short.append((motion, split, s.model_copy(update={"duration_s": 1.0})))
    monkeypatch.setattr(virtual_tank, "paper_experiment_plan", lambda: short)
    out = tmp_path / "murky_tank"
    assert cli.main(["dataset", str(out), "--plant", "murky", "--workers", "1"]) == 0
    ds = load_dataset(out)
    murky = PLANTS["murky"]
    assert ds.plant["median"] == "centred" and ds.plant["stray_current_direction_deg"] == 30.0
    assert ds.truth["straight"] == TABLE3["straight"]
    # what the dataset holds is what the plant records: the first experiment again, by hand
    motion, _split, scenario = short[0]
    again = virtual_tank.record_experiment(load_robot(), scenario, motion, TABLE3[motion],
                                           murky.settings, 0)
    written = ds.train[motion][0]
    assert written.name == scenario.name and written.camera["median"] == "centred"
    assert np.allclose(written.position_m, again.position_m, atol=1e-6)
    plain = virtual_tank.record_experiment(load_robot(), scenario, motion, TABLE3[motion],
                                           TankSettings(), 0)
    assert not np.allclose(plain.position_m[: len(again.t_s)], again.position_m[: len(plain.t_s)])


def test_an_unknown_plant_is_refused_naming_the_known_ones(lab, capsys, tmp_path):
    assert cli.main(["dataset", str(tmp_path / "x"), "--plant", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'nosuch'" in err
    assert "'murky'" in err and "'head_tail'" in err
    assert cli.main(["estimate-bench", "--bands", "head_tail,nosuch"]) == 2
    err = capsys.readouterr().err
    assert "unknown test plant 'nosuch'; known plants: " in err and "murky" in err
    assert not (tmp_path / "x").exists()


def test_a_plant_is_registered_once_under_its_own_name(monkeypatch):
    monkeypatch.setattr(PLANTS, "_entries", dict(PLANTS._entries))
    with pytest.raises(DuplicateNameError, match="'head_tail' is already registered"):
        register_plant(Plant("head_tail", "another head", TankSettings()))
    with pytest.raises(RegistryError, match="'tidal': its water's law 'tidal' is not a registered"):
        register_plant(Plant("tidal", "tidal water", TankSettings(), law="tidal"))
    with pytest.raises(RegistryError, match="expected an eelhost.data.plants.Plant"):
        PLANTS.add("settings", TankSettings(), "a tank's settings are not a plant")
