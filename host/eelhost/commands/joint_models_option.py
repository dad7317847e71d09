"""``--joint-models``: the joint models the estimator's model comparison tries.

By default the comparison tries the joint models offered by default and the robot file's own
(``eelsim.joints.default_grid_models``); a model that is not offered by default (``pd_limited``,
the PD loop on a fitted torque-speed line) is tried when this option names it (docs/estimation.md,
"Model comparison").
"""

from __future__ import annotations

import argparse

from eelsim.joints import JOINT_MODELS, default_grid_models


def joint_model_names(text: str) -> tuple[str, ...]:
    """Comma-separated names of registered joint models.

    Raises
    ------
    argparse.ArgumentTypeError
        For an empty list or an unknown name (the message lists the known ones).
    """
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in JOINT_MODELS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(
            f"expected joint models from {', '.join(sorted(JOINT_MODELS))}, got {text!r}")
    return names


def add_joint_models_option(p: argparse.ArgumentParser) -> None:
    """Add ``--joint-models MODEL,...`` (default: None, the comparison's own default)."""
    p.add_argument("--joint-models", type=joint_model_names, metavar="MODEL,...",
                   help="joint models the comparison tries (default: "
                   + ",".join(default_grid_models())
                   + " and the robot file's; e.g. pd,pd_limited,servo adds the PD loop on a "
                   "fitted torque-speed line)")
