"""Experiments on disk (the estimation format, datasets) and the virtual tank that makes them."""
from eelhost.data import plant_laws  # noqa: F401  (registers the plants-only fluid laws)
