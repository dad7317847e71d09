"""The simulation backends are a registry: a package's own backend reaches ``--backend`` and the
evaluator by name, with no list edited; an unknown one is refused naming the known ones (issue 30)."""

import pytest
from test_plugins import help_of

from eelhost.estimation.evaluate import BACKENDS, EstimationError, backend_named
from eelhost.estimation.reference_backend import ReferenceBackend


class Recording:
    """A toy backend that remembers how it was made."""

    def __init__(self, workers, map_function):
        self.workers, self.map_function = workers, map_function


@pytest.fixture
def toy(monkeypatch):
    BACKENDS.names()  # the built-ins first
    monkeypatch.setattr(BACKENDS, "_entries", dict(BACKENDS._entries))
    BACKENDS.add("toy", Recording, "a user's backend that records its settings")


def test_a_registered_backend_is_offered_and_made_by_name(toy, capsys):
    text = " ".join(help_of(capsys, "estimate").split())
    assert "--backend {auto,batch,reference,toy}" in text
    assert "toy: a user's backend that records its settings" in text
    made = backend_named("toy", 3, print)
    assert isinstance(made, Recording) and (made.workers, made.map_function) == (3, print)
    assert isinstance(backend_named("reference", 2), ReferenceBackend)


def test_an_unknown_backend_is_refused_naming_the_known_ones(toy):
    with pytest.raises(EstimationError,
                       match="unknown simulation backend 'gpu'; known backends: batch, reference, "
                       "toy, or auto"):
        backend_named("gpu")
