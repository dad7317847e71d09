"""``--joint-models``: the joint models the estimator's model comparison tries.

By default the comparison tries the joint models offered by default and the robot file's own
(``eelsim.joints.default_grid_models``); a model that is not offered by default (``pd_limited``,
the PD loop on a fitted torque-speed line) is tried when this option names it (docs/estimation.md,
"Model comparison").
"""

from __future__ import annotations

import argparse

from eelhost.commands.common import registered_names
from eelsim.joints import JOINT_MODELS, default_grid_models

joint_model_names = registered_names(JOINT_MODELS, "joint models")
"""``--joint-models``: comma-separated names of registered joint models (argparse refuses an
empty list or an unknown name, listing the known ones)."""


def add_joint_models_option(p: argparse.ArgumentParser) -> None:
    """Add ``--joint-models MODEL,...`` (default: None, the comparison's own default)."""
    p.add_argument("--joint-models", type=joint_model_names, metavar="MODEL,...",
                   help="joint models the comparison tries (default: "
                   + ",".join(default_grid_models())
                   + " and the robot file's; e.g. pd,pd_limited,servo adds the PD loop on a "
                   "fitted torque-speed line)")
