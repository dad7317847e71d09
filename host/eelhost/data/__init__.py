"""Experiments on disk (the estimation format, datasets) and the virtual tank that makes them."""
