"""Which candidate model to trust: leave-one-gait-out cross-validation (docs/estimation.md).

The candidates are the whole grid of the twin's joint models and candidate fluid laws
(:func:`candidate_spaces`), each with separate straight and turning coefficient sets (the paper's
e_1*, e_2*); the best of them (:data:`ONE_SET_CANDIDATES`) are tried with one coefficient set for
every motion too. For each fit every training experiment, one gait (amplitude, frequency), is held
out in turn: the candidate is refitted on the others and scored on the held-out one by the
fitness's per-experiment error (docs/estimation.md, "Fitness"). A model that only fits better
because it has more freedom to absorb the training gaits' noise or the plant's missing physics
predicts held-out gaits worse.

**The choice does not depend on the robot file.** Every candidate is fitted from its own starts
(:func:`multi_start_fit`): a short CMA-ES search from the middle of its bounds (its first
generation spread over the whole box), polished by the minimax trust region, then again from
every other candidate's fit carried over by name (:func:`carry_over`); never from the robot
file's values. The other joint
model's fixed parameters are the bundled robot file's that uses it, so from either bundled robot
file the grid, the starts and therefore the scores are the same (tested).

**The screen: the budget where it matters.** The grid (every joint model x every candidate law
and its lift variant: twenty candidates) is too large for every candidate's full search. So
every candidate is first fitted and scored cheaply (:func:`_screen`: a :data:`SCREEN_BUDGET`
CMA-ES search, polished :data:`SCREEN_ITERATIONS` times, restarted from every other candidate's
screening fit carried over by name, its folds refitted :data:`SCREEN_FOLD_ITERATIONS` times);
the :data:`SURVIVORS` best by the screen's mean held-out error, of those within
:data:`SURVIVOR_FACTOR` of the best, get the full search (:func:`pass_screen`). This is one rung
of successive halving (Jamieson and Talwalkar, AISTATS 2016): the screen's errors come from
shorter fits. **No family is dropped for lack of search**: every joint model's best candidate
passes too (:func:`screen_rank`: one whose short search failed, when all of that joint model's
did), and so does every law family's best (a law with or without its lift, :func:`family`)
within :data:`FAMILY_FACTOR` of the best. **A lift variant passes with its base**
(:func:`lift_variants`): it nests its base (its lift, drag rise and stall off, :data:`ABSENT`,
are the base's law), and its restart may start from its base's own screening search with them
off, yet its screen error may be several times its base's: the restart runs beside the base's
(so it cannot start from the base's restarted fit) and the held-out error comes from
two-iteration refits of each fold, in which its extra coefficients move (on ``no_added_mass``
seed 44, ``servo x linear_quadratic_lift`` was screened out at 0.6951 m beside its base's full
search at 0.3163 m, where on seed 31 it had met every target). So whenever a candidate passes,
its variant passes too, to the middle rung unless it is among the best few on its own
(docs/estimation.md, "Model comparison"); the reverse does not hold (the base does not nest
the variant). The survivors' full search starts warm: from its own
CMA-ES search, from the candidate's screening fit, and from the best of every candidate's
screening fit carried over (the screened-out ones' too). Those dropped are shown with the
screen's figures, marked, and never recommended.

**The middle rung.** A survivor that passes only as a family's or joint model's best, or with
its base (not among the screen's best few, :func:`best_few`; :func:`middle_rung`) is the second
rung of successive halving: it first gets a medium budget (:func:`_middle_stage`: a
:data:`MIDDLE_BUDGET` CMA-ES search seeded as the full one, from the full search's starts,
polished, its current fitted and its folds refitted as the screen's), run beside the others'
own searches in the same barrier.
It goes on to the full search only when its middle-rung mean held-out error comes within
:data:`SURVIVOR_FACTOR` of the lowest of the screen's and the middle rung's (or its middle rung
failed: :func:`past_middle_rung`); otherwise it stops there, shown with the middle rung's
figures, marked, and never recommended (docs/estimation.md, "Model comparison").

**Joint models that join after the screen.** A joint model that is not offered by default but
``offered_after_screen`` (the PD loop on the servo's torque-speed line, ``pd_limited``) joins the
default grid after the screen with every base law of the grid (a law without its lift) and the
:data:`AFTER_SCREEN_LAWS` laws whose candidates the screen ranks best (:func:`after_screen_laws`:
the screen ranks laws on the wrong joints by how well they absorb the joints' misfit, not by the
water, so the water's own law may rank last), screened the same way (restarted from every
screening fit, its line starting off: :data:`ABSENT`); a joined candidate gets the full search
when it would pass the screen among all candidates (:func:`screen_survivors`), beside the grid's
own survivors, which it never displaces; its best is not passed as a joint model's best (it
nests the PD model with the same law: the line off). Its candidates follow the grid's in the
order of the table.

**The finalists.** The full search's fits still depend on their starts: where the joints bind,
a fit whose joint parameters took up the water's misfit (a stall torque three times the
plant's) sits in a basin its own polish never leaves, and the held-out errors then rank laws
by their fits' luck. So the :data:`FINALISTS` best by mean held-out error (:func:`finalists`)
are refitted before the choice (:func:`_final`): polished from every fully searched
candidate's fits carried over by name (their own of the other motions too: the full stage
polishes only the carried start that scores best before its polish, and a start's score says
little of where its polish ends), and from their joint parameters spread over their whole
bounds (:func:`spread_starts`, from their own fit and the best carried one), of which the
:data:`FINAL_POLISHED` best, :data:`FINAL_SEPARATION` apart (:func:`separated`), are polished. A refit at most :data:`IMPROVED` times the fit's
fitness replaces it, and its current, folds and excursion are scored again. The table marks a
full fit more than :data:`MISFIT_FACTOR` times its motion's best (:func:`misfit_ratios`).

**A failure is not a score.** A fold whose refit fails (a penalty on a training gait or on the
held-out one) is refitted from the candidate's next start; a candidate whose fold still fails is
marked failed, shown as such, and never ranked by a penalty-inflated mean.

**Between the training gaits.** The folds of a corner design only extrapolate, so every fitted
candidate also swims the gaits between its training gaits, and one whose mean speed there leaves
the recorded speeds around them by more than
:data:`~eelhost.estimation.neighbours.SANE_FACTOR` is not recommended while a sane one ran
(:mod:`eelhost.estimation.neighbours`).

The recommendation is the sane candidate with the lowest mean held-out error over every held-out gait;
one with fewer parameters that nests in it (:func:`nested_in`: the best with terms switched off)
is preferred when its mean is within the larger of ``TIE`` of the best's and one standard error
of the best's mean over its folds (the one-standard-error rule of
cross-validation: Breiman, Friedman, Olshen and Stone, *Classification and Regression Trees*,
1984, section 3.4.3; Hastie, Tibshirani and Friedman, *The Elements of Statistical Learning*, 2009,
section 7.10). A richer model's lower error within the folds' own spread is not evidence that it
predicts better: a lift variant nests its base law, and on water without lift its extra
coefficients fit noise (docs/estimation.md, "Model choice"). The rule is one of nested models
(a path of growing complexity); between families that do not nest (Lighthill's law and
Morison's) fewer parameters say nothing about which predicts, and the lower error is chosen.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from eelhost.data.experiments import Dataset, Experiment
from eelhost.estimation.evaluate import EstimationError, Evaluator, count_runs, many_problems
from eelhost.estimation.joint_fit import (
    ParameterError,
    bundled_joints,
    joint_fit,
    joint_model_name,
)
from eelhost.estimation.local import FAILED, polish_minimax_many
from eelhost.estimation.methods import CURRENT_POLISH_ITERATIONS, FitSettings
from eelhost.estimation.neighbours import SANE_FACTOR, neighbour_excursion
from eelhost.estimation.optimise import fit_cmaes
from eelhost.estimation.pipeline import training_experiments
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law
from eelsim.fluid.lift import LiftLaw
from eelsim.joints import after_screen_models, get_joint_model

log = logging.getLogger(__name__)

TIE = 0.02  # relative: held-out errors this close count as equal
POLISH_ITERATIONS = 8  # minimax iterations of every fit of the comparison
FOLD_ITERATIONS = 4  # and of a fold's refit, which starts from the fit on every gait
SEARCH_BUDGET = 600  # CMA-ES candidates of a candidate model's own search, per fit
SCREEN_BUDGET = 150  # CMA-ES candidates of every candidate's screening search, per fit
SCREEN_ITERATIONS = 4  # minimax iterations of a screening fit (own search, carried-over starts)
SCREEN_FOLD_ITERATIONS = 2  # and of a screening fold's refit
SURVIVORS = 4  # at most this many candidates pass the screen to the full search
SURVIVOR_FACTOR = 2.0  # and only those within this factor of the screen's best mean held-out error
FAMILY_FACTOR = 4.0  # a law family's best passes too when within this factor of the screen's best
MIDDLE_BUDGET = SEARCH_BUDGET // 2  # CMA-ES candidates of the middle rung's search, per fit
# a term the other model lacks starts switched off (a lift variant's lift and drag rise)
# and the torque-speed line of a joint model that has one (pd_limited) at its bounds' far end,
# where the gaits never reach it: the plain PD loop
ABSENT = {"C_L": 0.0, "C_D_alpha": 0.0, "alpha_stall": float(np.pi / 2),  # pi/2: no stall
          "servo_max_torque_nm": np.inf, "servo_max_speed_rad_s": np.inf}  # clipped to the bounds
AFTER_SCREEN_LAWS = 2  # the screen's best laws a joint model that joins after it is tried with
# (besides every base law of the grid: after_screen_laws)
FINALISTS = 3  # the comparison's best few, refitted from more starts before the choice
# where the joint parameters' spread starts sit in their bounds (fractions; every combination)
SPREAD_LEVELS = (0.1, 0.3, 0.5, 0.7, 0.9)
# and each joint parameter alone at this many even steps over its bounds, the others kept: on
# the servo line the fitness has a valley a fiftieth of the stall torque's range wide
SPREAD_STEPS = 61
FINAL_POLISHED = 4  # a finalist's best new starts polished, per fit, each this far apart:
FINAL_SEPARATION = 0.25  # in the unit cube of its still-water parameters (Euclidean)
IMPROVED = 0.9  # a finalist's refit replaces its fit (scored again) when this much lower or more
MISFIT_FACTOR = 3.0  # a full fit this many times the best full fit of its motion is marked
ONE_SET_CANDIDATES = 1  # the best separate-set models also tried with one set for all motions
ONE_SET = "one set"  # the suffix of a one-set candidate's name


def carry_over(values: Mapping[str, float], space: ParameterSpace, default: np.ndarray) -> np.ndarray:
    """A start in ``space`` from another model's parameters, by name.

    A name the other model has is taken as it is; a law's split coefficient (``C_f_lin``,
    ``C_f_quad``) takes its unsplit one (``C_f``), the ``galilean`` law being the split law with
    both equal (from the paper's law this is only a start: the split law adds the reactive
    terms); a term the other model lacks and that can be switched off (:data:`ABSENT`: a lift
    variant's ``C_L`` and ``C_D_alpha``, its ``alpha_stall`` at pi/2; a torque-speed line at its
    upper bounds) starts off, so a ``<law>_lift`` candidate starts from its base law's fit
    exactly; anything else keeps ``default``. The result is clipped to the bounds.

    Parameters
    ----------
    values : mapping of str to float
    space : ParameterSpace
    default : ndarray, shape (K,)

    Returns
    -------
    ndarray, shape (K,)
    """
    out = np.array(default, dtype=float)
    for i, name in enumerate(space.names):
        base = name.rsplit("_", 1)[0] if name.endswith(("_lin", "_quad")) else name
        if name in values:
            out[i] = values[name]
        elif base in values:
            out[i] = values[base]
        elif name in ABSENT:
            out[i] = ABSENT[name]
    b = space.bounds
    return np.clip(out, b[:, 0], b[:, 1])


@dataclass
class CandidateScore:
    """One candidate model's cross-validation.

    Attributes
    ----------
    model : str
        "<joint model> x <fluid law>", with ", one set" for one coefficient set for every motion.
    parameters : int
        Its parameter count over all its coefficient sets.
    fitness : dict of str to float
        Its fitness on all training experiments, per fit ("straight", "turning"; "joint" for
        one set).
    held_out : dict of str to ndarray
        Per fit, the error of each held-out gait (in training order); NaN for a fold whose
        every refit failed.
    simulations : int
    space : ParameterSpace or None
        The candidate's parameter space (what a refit with it fits).
    values : dict of str to ndarray
        Per fit, its parameters fitted on all training experiments.
    failed : str or None
        Why the candidate failed (a fold none of whose refits ran), None when it did not.
    screened_out : bool
        Whether the candidate was dropped by the screen: its figures are then the screen's
        (short search, short polish), and it is never recommended.
    between : dict of str to float
        Per fit, how far its predictions of the gaits between its training gaits leave the
        speeds the recordings bracket (:func:`eelhost.estimation.neighbours.neighbour_excursion`:
        1 inside; absent for a screened-out candidate).
    middle_rung : bool
        Whether the candidate, passed by the screen only as a family's or joint model's best,
        stopped at the middle rung (:func:`past_middle_rung`): its figures are then the middle
        rung's (a medium search, the screen's polish and folds); ``screened_out`` is set too, so
        it is never recommended nor compared as a full fit.
    """

    model: str
    parameters: int
    fitness: dict[str, float] = field(default_factory=dict)
    held_out: dict[str, np.ndarray] = field(default_factory=dict)
    simulations: int = 0
    space: ParameterSpace | None = None
    values: dict[str, np.ndarray] = field(default_factory=dict)
    failed: str | None = None
    screened_out: bool = False
    between: dict[str, float] = field(default_factory=dict)
    middle_rung: bool = False

    @property
    def excursion(self) -> float:
        """The worst excursion between training gaits over its fits (1 when none was checked)."""
        return max(self.between.values(), default=1.0)

    @property
    def sane(self) -> bool:
        """Whether its predictions between its training gaits stay within ``SANE_FACTOR``."""
        return self.excursion <= SANE_FACTOR

    @property
    def one_set(self) -> bool:
        """Whether the candidate fits one coefficient set for every motion."""
        return "joint" in self.values or self.model.endswith(ONE_SET)

    @property
    def mean_held_out(self) -> float:
        """Mean held-out error over every fold of every fit (inf for a failed candidate)."""
        errors = np.concatenate(list(self.held_out.values()))
        if self.failed or not np.all(np.isfinite(errors)):
            return float("inf")
        return float(np.mean(errors))

    @property
    def standard_error(self) -> float:
        """Standard error of :attr:`mean_held_out` over the folds (0 for one fold; inf if failed)."""
        errors = np.concatenate(list(self.held_out.values()))
        if self.failed or not np.all(np.isfinite(errors)):
            return float("inf")
        if errors.size < 2:
            return 0.0
        return float(np.std(errors, ddof=1) / np.sqrt(errors.size))

    @property
    def worst_held_out(self) -> float:
        """Largest held-out error (inf for a failed candidate)."""
        errors = np.concatenate(list(self.held_out.values()))
        if self.failed or not np.all(np.isfinite(errors)):
            return float("inf")
        return float(np.max(errors))


def recommend(scores: Sequence[CandidateScore]) -> CandidateScore | None:
    """The candidate to trust (module docstring): lowest mean held-out error, ties to the simpler.

    A tie is a mean within the larger of ``TIE`` of the best's and the best's standard error;
    the simpler candidate of a tie is chosen only where it nests in the best (:func:`nested_in`).
    Only candidates that stay sane between their training gaits (:attr:`CandidateScore.sane`)
    are ranked; when none does, those within ``SANE_FACTOR`` of the smallest excursion are (the
    least implausible).

    Failed candidates and those the screen dropped are never recommended; None when every
    candidate failed.
    """
    ran = [c for c in scores if np.isfinite(c.mean_held_out) and not c.screened_out]
    if not ran:
        return None
    least = min(c.excursion for c in ran)
    ran = [c for c in ran if c.sane or c.excursion <= SANE_FACTOR * least]
    best = min(ran, key=lambda c: c.mean_held_out)
    margin = max(best.mean_held_out * TIE, best.standard_error)
    # the simpler model of a tie is preferred only where it is the best with terms switched off
    # (nested_in): between families that do not nest, fewer parameters say nothing about which
    # predicts (docs/estimation.md, "Held-out paths and the servo line: ties go to a nested
    # model")
    close = [c for c in ran if c.mean_held_out <= best.mean_held_out + margin
             and (c is best or nested_in(c.model, best.model))]
    return min(close, key=lambda c: (c.parameters, c.mean_held_out))


def _extends(rich: str, simple: str) -> bool:
    """Whether joint model ``rich`` extends ``simple`` (the PD loop on the servo line, the PD loop).

    ``JointModel.table_from``: a model that can make its table from the other's extends it.
    """
    if rich == simple:
        return True
    try:
        return get_joint_model(rich).table_from(bundled_joints(simple)) is not None
    except (KeyError, ValueError, ParameterError):  # a name the twin does not know
        return False


def nested_in(simple: str, rich: str) -> bool:
    """Whether candidate ``simple`` is candidate ``rich`` with some of its terms switched off.

    By the candidates' names (:func:`model_parts`): the same law or the law without its lift
    (a lift variant with C_L = C_D_alpha = 0 is its base law), the same joint model or one the
    richer one extends (the servo line at its bounds' far end is the plain PD loop), and one set
    for every motion where the richer one has one, or separate sets (one set is both sets
    equal). Lighthill's and Morison's laws, or PD and servo joints, do not nest.

    Parameters
    ----------
    simple, rich : str
        Candidate names, "<joint model> x <law>[, one set]".

    Returns
    -------
    bool
        True also when the two are the same candidate.
    """
    simple_joint, simple_law = model_parts(simple)
    rich_joint, rich_law = model_parts(rich)
    laws = simple_law in (rich_law, family(rich)[1])  # the same law, or it without its lift
    sets = simple.endswith(ONE_SET) or not rich.endswith(ONE_SET)
    return laws and sets and _extends(rich_joint, simple_joint)


def candidate_spaces(
    dataset: Dataset, laws: Sequence[str], current: bool, joint_models: Sequence[str] | None
) -> list[ParameterSpace]:
    """The joint model x law grid, in a fixed order (joint models, then laws, by name).

    Every joint model other than the robot file's brings the ``[joints]`` table of the bundled
    robot file that uses it (:func:`eelhost.estimation.joint_fit.joint_fit`), so the grid is the
    same from either bundled robot file.
    """
    from eelsim.fluid import get_fluid_law
    from eelsim.joints import default_grid_models

    # unless told which: the models offered by default and the robot file's own
    models = (default_grid_models(joint_model_name(dataset.robot)) if joint_models is None
              else sorted(set(joint_models)))
    return [ParameterSpace(get_fluid_law(law), joint_fit(dataset.robot, model), current=current)
            for model in models for law in sorted(set(laws))]


def after_screen_laws(scores: Sequence[CandidateScore], count: int = AFTER_SCREEN_LAWS,
                      grid_laws: Sequence[str] = ()) -> list[str]:
    """The laws a joint model that joins after the screen is tried with.

    The ``count`` distinct laws (a lift variant is a law of its own here) of the screened
    candidates best by :func:`screen_rank`, on any joint model, in that order; then every base
    law of ``grid_laws`` (one that is not a ``<law>_lift`` variant) not yet among them, in the
    grid's order. Why the base laws (docs/estimation.md, "Model comparison", "The servo line
    joins after the screen"): where the joints bind, every candidate of the grid swims the wrong
    joints, and the screen ranks the laws by how much of the joints' misfit they absorb, not by
    the water; on ``servo_limits`` (Morison water) the screen ranked ``morison`` among the last
    and the joined candidates' turning fits misfit 7 times the plant's own fitness. Each law
    family's simplest member is therefore tried on the joined joints; a lift variant (which nests
    its base law) joins where the screen ranks it best.
    """
    laws: list[str] = []
    for score in sorted(scores, key=screen_rank):
        if len(laws) == count:
            break
        law = model_parts(score.model)[1]
        if law not in laws:
            laws.append(law)
    laws += [law for law in grid_laws
             if law not in laws and not isinstance(get_fluid_law(law), LiftLaw)]
    return laws


@dataclass
class _Fitted:
    """A candidate's fits on one set of experiments, best first."""

    values: list[np.ndarray]
    fitness: list[float]


def multi_start_fit(
    ev: Evaluator,
    seed: int,
    extra_starts: Sequence[np.ndarray] = (),
    iterations: int = POLISH_ITERATIONS,
    budget: int = SEARCH_BUDGET,
    warm: Sequence[np.ndarray] = (),
) -> _Fitted:
    """Fit ``ev.space``'s law and joints in still water from its own starts (module docstring).

    Never from the robot file's values: a CMA-ES search of ``budget`` candidates from the middle
    of the bounds (its first generation spread over the whole box; seeded), the best of
    ``extra_starts`` (screened: other candidates' fits carried over), and every ``warm`` start
    (the candidate's own earlier fits, e.g. its screening fit); each polished by the minimax
    trust region.

    Returns
    -------
    _Fitted
        The fits in the still-water space (without the current), best first.
    """
    still = replace(ev.space, current=False)
    still_ev = ev.with_space(still) if ev.space.current else ev
    k = still.size
    begins = []
    if budget > 0:
        begins.append(fit_cmaes(still_ev.fitness, still, seed, budget).values)
    begins += [np.asarray(w, dtype=float)[:k] for w in warm]
    if len(extra_starts):
        pts = np.asarray(extra_starts, dtype=float)[:, :k]
        begins.append(pts[int(np.argmin(still_ev.fitness(pts)))])
    results = polish_minimax_many(many_problems(still_ev, [None] * len(begins)), still,
                                  np.array(begins), iterations)
    if still_ev is not ev:
        ev.count_from(still_ev)
    ranked = sorted(results, key=lambda r: r.fitness)
    return _Fitted([np.asarray(r.values, float) for r in ranked], [r.fitness for r in ranked])


def _with_current(ev: Evaluator, still: _Fitted, iterations: int,
                  current_iterations: int = CURRENT_POLISH_ITERATIONS) -> _Fitted:
    """The still-water fits in ``ev.space``: the best polished with the ambient current.

    The current is fitted from still water after the law and joints (the two stages of
    :func:`eelhost.estimation.methods.run_fit`); the other fits follow in still water, as starts
    for a failing fold.
    """
    if not ev.space.current:
        return still
    zeros = np.zeros(len(ev.space.current_names))
    begins = [np.concatenate([v, zeros]) for v in still.values]
    best = polish_minimax_many(many_problems(ev, [None]), ev.space, np.array(begins[:1]),
                               max(iterations, current_iterations))[0]
    return _merge(_Fitted([np.asarray(best.values, float)], [best.fitness]),
                  _Fitted(begins[1:], still.fitness[1:]))


def _folds(
    ev: Evaluator, fitted: _Fitted, iterations: int
) -> tuple[np.ndarray, str | None]:
    """Leave-one-out errors of a candidate on ``ev``'s experiments, refitting failing folds.

    Every fold is refitted from the candidate's best fit first (all folds polished together);
    a fold whose refit fails on a training gait or whose held-out run fails is refitted from the
    candidate's next fit, and so on. Returns the held-out errors (NaN where every start failed)
    and why the candidate failed (None if no fold did).
    """
    n = len(ev.prepared)
    errors = np.full(n, np.nan)
    todo = list(range(n))
    for start in fitted.values:
        if not todo:
            break
        refits = polish_minimax_many(many_problems(ev, todo), ev.space,
                                     np.tile(start, (len(todo), 1)), iterations)
        held = ev.errors(np.array([r.values for r in refits]))
        still_failing = []
        for j, refit in zip(todo, refits, strict=True):
            if refit.fitness < FAILED and held[todo.index(j), j] < FAILED:
                errors[j] = held[todo.index(j), j]
            else:
                still_failing.append(j)
        todo = still_failing
    if todo:
        names = ", ".join(ev.prepared[j].experiment.name for j in todo)
        return errors, f"held out {names}: every refit fails (penalty)"
    return errors, None


def cross_validate(
    dataset: Dataset,
    fits: Sequence[str] | Mapping[str, object],
    settings: FitSettings,
    laws: Sequence[str] | None = None,
    iterations: int = POLISH_ITERATIONS,
    say: Callable[[str], None] | None = None,
    joint_models: Sequence[str] | None = None,
    one_set: int = ONE_SET_CANDIDATES,
    budget: int = SEARCH_BUDGET,
    fold_iterations: int = FOLD_ITERATIONS,
    screen_budget: int = SCREEN_BUDGET,
    survivors: int = SURVIVORS,
    final: int = FINALISTS,
    middle_budget: int | None = None,
) -> list[CandidateScore]:
    """Leave-one-gait-out cross-validation of the candidate models (module docstring).

    Parameters
    ----------
    dataset : Dataset
    fits : sequence of str
        The separate fits to compare on ("straight", "turning"); a mapping's keys are taken.
    settings : FitSettings
        The evaluator's backend and clock search, the seed of the starts, whether the
        ambient current is fitted, and the worker processes of the independent fits
        (``jobs``; the scores do not depend on it).
    laws : sequence of str, optional
        Fluid laws of the grid (default: :func:`default_laws`).
    iterations : int
        Polish iterations per fit on every training gait.
    say : callable, optional
        Gets a line per candidate.
    joint_models : sequence of str, optional
        Joint models of the grid (default: every one the twin has).
    one_set : int
        How many of the best separate-set models are tried with one set for every motion too
        (needs two fits; 0: none).
    budget : int
        CMA-ES candidates of each candidate model's own search, per fit.
    fold_iterations : int
        Polish iterations of a fold's refit.
    screen_budget : int
        CMA-ES candidates of every candidate's screening search, per fit (0: no screen, every
        candidate gets the full search). The screen runs only when the grid has more than
        ``survivors`` candidates.
    survivors : int
        At most this many candidates pass the screen (:func:`pass_screen`).
    final : int
        How many of the best fully searched candidates are refitted from more starts before
        the choice (:func:`finalists`; 0: none).
    middle_budget : int, optional
        CMA-ES candidates of the middle rung's search, per fit, for a candidate the screen
        passes only as a family's or joint model's best (:func:`middle_rung`; 0: no middle
        rung, every survivor gets the full search). Default: the same share of ``budget`` as
        :data:`MIDDLE_BUDGET` of :data:`SEARCH_BUDGET` (half).

    Returns
    -------
    list of CandidateScore
        The grid's candidates in order (those the screen dropped with the screen's figures and
        ``screened_out``, those stopped at the middle rung with its figures, ``screened_out``
        and ``middle_rung``), then the one-set ones.

    Raises
    ------
    EstimationError
        When a fit has fewer than two training experiments.
    """
    motions = list(fits)
    if middle_budget is None:
        middle_budget = budget * MIDDLE_BUDGET // SEARCH_BUDGET
    laws = list(laws) if laws is not None else default_laws()
    for motion in motions:
        if len(training_experiments(dataset, motion)) < 2:
            raise EstimationError(
                f"cross-validation of {motion!r} needs two training experiments or more"
            )
    spaces = candidate_spaces(dataset, laws, settings.fit_current, joint_models)

    def evaluator(space: ParameterSpace, experiments: list[Experiment]) -> Evaluator:
        return Evaluator(dataset.robot, experiments, backend=settings.backend,
                         align_s=settings.align_s, space=space)

    evs = {(i, m): evaluator(s, training_experiments(dataset, m))
           for i, s in enumerate(spaces) for m in motions}
    screen_scores: dict[int, CandidateScore] = {}
    screen_fits: dict[tuple[int, str], _Fitted] = {}
    middle: dict[int, CandidateScore] = {}
    with Workers(settings.jobs, len(evs)) as workers:
        alive = list(range(len(spaces)))
        trial: list[int] = []
        if screen_budget > 0 and len(spaces) > survivors:
            screen_fits, screen_scores = _screen(workers, spaces, evs, motions, settings.seed,
                                                 screen_budget)
            joining: list[str] = []
            grid_size = len(spaces)
            if joint_models is None:
                joining = after_screen_models(sorted({s.joints.model for s in spaces}))
            if joining:
                chosen = after_screen_laws(list(screen_scores.values()), grid_laws=laws)
                first = len(spaces)
                spaces = spaces + [
                    ParameterSpace(get_fluid_law(law), joint_fit(dataset.robot, model),
                                   current=settings.fit_current)
                    for model in joining for law in chosen]
                for i in range(first, len(spaces)):
                    for m in motions:
                        evs[(i, m)] = evaluator(spaces[i], training_experiments(dataset, m))
                log.info("model comparison: %s join after the screen with %s",
                         ", ".join(joining), ", ".join(chosen))
                more_fits, more_scores = _screen(
                    workers, spaces, evs, motions, settings.seed, screen_budget,
                    screened=screen_fits, keys=[(i, m) for i in range(first, len(spaces))
                                                for m in motions])
                screen_fits.update(more_fits)
                screen_scores.update(more_scores)
            alive = screen_survivors([screen_scores[i] for i in range(len(spaces))],
                                     grid_size, survivors, set(joining))
            log.info("model comparison: %d of %d candidates pass the screen", len(alive),
                     len(spaces))
            if middle_budget > 0:
                trial = middle_rung([screen_scores[i] for i in range(len(spaces))],
                                    grid_size, survivors, set(joining))
        full, middle = _full(workers, spaces, evs, motions, alive, screen_fits, settings.seed,
                             iterations, fold_iterations, budget,
                             seed_offset=1 if screen_fits else 0, trial=trial,
                             middle_budget=middle_budget,
                             screened_scores=[screen_scores[i] for i in sorted(screen_scores)])
        if final > 0:
            _final(workers, spaces, evs, full, iterations, fold_iterations, final)
    scores = []
    for i in range(len(spaces)):
        if i in full:
            score = full[i]
        elif i in middle:
            score = middle[i]
            score.screened_out = score.middle_rung = True
        else:
            score = screen_scores[i]
            score.screened_out = True
        _said(score, say)
        scores.append(score)
    if one_set and len(motions) > 1:
        ranked = sorted((s for s in scores if np.isfinite(s.mean_held_out)
                         and not s.screened_out), key=lambda s: s.mean_held_out)
        for best in ranked[:one_set]:
            scores.append(_one_set(dataset, best, motions, evaluator, settings.seed,
                                   iterations, fold_iterations, budget))
            _said(scores[-1], say)
    return scores


def default_laws() -> list[str]:
    """The comparison's fluid laws by default: the laws that declare themselves candidates.

    :func:`eelsim.fluid.candidate_laws`: the twin's five candidate laws and their ``<law>_lift``
    variants (:mod:`eelsim.fluid.lift`), which are candidates because their base law is; the
    screen (:func:`pass_screen`) keeps the grid's cost near that of the full search of four
    candidates. A law registered without ``candidate = True`` is fitted only when named.
    """
    from eelsim.fluid import candidate_laws

    return list(candidate_laws())


def pass_screen(scores: Sequence[CandidateScore], survivors: int = SURVIVORS,
                factor: float = SURVIVOR_FACTOR,
                family_factor: float = FAMILY_FACTOR,
                joined: set[str] | frozenset[str] = frozenset()) -> list[int]:
    """Which screened candidates get the full search: their positions in ``scores``, in order.

    The ``survivors`` lowest mean held-out errors of the screen, of those within ``factor`` of
    the lowest; then every family's best, so that no family is dropped for lack of search
    (module docstring, "The screen"): every joint model's best candidate (:func:`screen_rank`:
    one that failed the screen too, when all of that joint model's did), and every law family's
    best (a law and its ``<law>_lift`` variant, on either joint model) within ``family_factor``
    of the lowest. Then every passing candidate's lift variant (:func:`lift_variants`: the same
    joint model and sets, its law with lift), however the screen scored it: the variant nests its
    base, so a screen error above the base's says only that the short fits have not found its lift
    (docs/estimation.md, "Model comparison"). When every candidate failed the screen, all pass (a
    short search may fail where the full one does not). A joint model in ``joined`` (one that
    joined after the screen with a few laws) has no joint model's best passed: its candidates
    pass on their errors (and with their base).
    """
    ran = [i for i, c in enumerate(scores) if np.isfinite(c.mean_held_out)]
    if not ran:
        return list(range(len(scores)))
    best = min(scores[i].mean_held_out for i in ran)
    passed = set(best_few(scores, survivors, factor))
    joints: dict[str, int] = {}
    laws: dict[str, int] = {}
    for i in sorted(range(len(scores)), key=lambda i: screen_rank(scores[i])):
        joint, law = family(scores[i].model)
        if joint not in joined:
            joints.setdefault(joint, i)
        if np.isfinite(scores[i].mean_held_out):
            laws.setdefault(law, i)
    passed |= set(joints.values())
    passed |= {i for i in laws.values() if scores[i].mean_held_out <= family_factor * best}
    variants = lift_variants(scores)
    passed |= {variants[i] for i in passed if i in variants}
    return sorted(passed)


def lift_variants(scores: Sequence[CandidateScore]) -> dict[int, int]:
    """Each candidate's lift variant among ``scores``: position of the base -> the variant's.

    The variant of ``<joint> x <law>`` is ``<joint> x <law>_lift`` with the same coefficient
    sets (:func:`model_parts`): it nests its base (lift and drag rise off, :data:`ABSENT`), so
    the base's fit is one of its fits and it passes the screen with its base (module
    docstring, "The screen").

    Parameters
    ----------
    scores : sequence of CandidateScore
        The screened candidates, named ``<joint> x <law>`` (with the one-set suffix or not).

    Returns
    -------
    dict of int to int
        For each candidate without lift whose variant is among ``scores``: its position there
        mapped to the variant's.
    """
    where = {(model_parts(c.model), c.model.endswith(ONE_SET)): i for i, c in enumerate(scores)}
    out: dict[int, int] = {}
    for i, c in enumerate(scores):
        joint, law = model_parts(c.model)
        variant = where.get(((joint, f"{law}_lift"), c.model.endswith(ONE_SET)))
        if not law.endswith("_lift") and variant is not None:
            out[i] = variant
    return out


def best_few(scores: Sequence[CandidateScore], survivors: int = SURVIVORS,
             factor: float = SURVIVOR_FACTOR) -> list[int]:
    """The screen's best few: the ``survivors`` lowest mean held-out errors within ``factor``.

    Their positions in ``scores``, in order; every position when every candidate failed (a
    short search may fail where the full one does not). The rest of :func:`pass_screen`'s
    survivors pass only as a family's or joint model's best.
    """
    ran = sorted((i for i, c in enumerate(scores) if np.isfinite(c.mean_held_out)),
                 key=lambda i: scores[i].mean_held_out)
    if not ran:
        return list(range(len(scores)))
    best = scores[ran[0]].mean_held_out
    return sorted(i for i in ran[:survivors] if scores[i].mean_held_out <= factor * best)


def middle_rung(scores: Sequence[CandidateScore], grid_size: int,
                survivors: int = SURVIVORS, joined: set[str] | frozenset[str] = frozenset(),
                ) -> list[int]:
    """The screen's survivors that get the middle rung before the full search, in order.

    Those that :func:`screen_survivors` passes only as a family's or joint model's best, or as
    a passing base's lift variant (:func:`lift_variants`): not among the :func:`best_few` of the
    grid (the first ``grid_size`` scores) for a grid candidate, nor of all the scores for a
    candidate that joined after the screen (module docstring, "The middle rung").
    """
    passed = screen_survivors(scores, grid_size, survivors, joined)
    sure = set(best_few(list(scores[:grid_size]), survivors))
    sure |= {i for i in best_few(list(scores), survivors) if i >= grid_size}
    return [i for i in passed if i not in sure]


def past_middle_rung(middle: Mapping[int, CandidateScore], screened: Sequence[CandidateScore],
                     factor: float = SURVIVOR_FACTOR) -> list[int]:
    """Which candidates of the middle rung go on to the full search: their positions, in order.

    Those whose middle-rung mean held-out error (``middle``, by position) is within ``factor``
    of the lowest of the screen's (``screened``) and the middle rung's, the same factor the
    screen's best few pass by; and those whose middle rung failed (a penalty is not an error:
    the full search decides). The screen's errors come from shorter fits than the middle
    rung's, so the comparison leans towards letting a candidate on.
    """
    errors = [c.mean_held_out for c in (*screened, *middle.values())]
    best = min((e for e in errors if np.isfinite(e)), default=np.inf)
    return sorted(i for i, c in middle.items()
                  if not np.isfinite(c.mean_held_out) or not np.isfinite(best)
                  or c.mean_held_out <= factor * best)


def screen_survivors(scores: Sequence[CandidateScore], grid_size: int,
                     survivors: int = SURVIVORS, joined: set[str] | frozenset[str] = frozenset(),
                     ) -> list[int]:
    """Who gets the full search when joint models joined after the screen (module docstring).

    The grid's own survivors (the first ``grid_size`` scores) are those :func:`pass_screen`
    passes among them alone, as if nothing had joined, so a joined candidate never displaces
    one; a joined candidate (after them) passes too when :func:`pass_screen` passes it among
    all the scores (``joined`` names its joint models).
    """
    own = pass_screen(list(scores[:grid_size]), survivors)
    every = pass_screen(list(scores), survivors, joined=joined)
    return sorted(set(own) | {i for i in every if i >= grid_size})


def model_parts(model: str) -> tuple[str, str]:
    """A candidate's joint model and law, from its name "<joint model> x <law>[, one set]"."""
    joint, _, law = model.split(ONE_SET)[0].rstrip(", ").partition(" x ")
    return joint, law


def family(model: str) -> tuple[str, str]:
    """A candidate's joint model and law family, from its name.

    The law family of ``morison`` and of its ``morison_lift`` variant is "morison"
    (:func:`model_parts`).
    """
    joint, law = model_parts(model)
    return joint, law.removesuffix("_lift")


def screen_rank(score: CandidateScore) -> tuple[int, float, float]:
    """How a screened candidate ranks, best first.

    By its mean held-out error; one that failed after all that ran, by the share of its folds
    that failed, then by its fitness summed over its fits (a failed fit's penalty counts).
    """
    if np.isfinite(score.mean_held_out):
        return (0, score.mean_held_out, 0.0)
    errors = np.concatenate(list(score.held_out.values()))
    return (1, float(np.mean(~np.isfinite(errors))), float(sum(score.fitness.values())))


def _add_to_score(
    scores: dict[int, CandidateScore], spaces: Sequence[ParameterSpace], motions: Sequence[str],
    i: int, m: str, fitted: _Fitted, held: Any, why: str | None, ev: Evaluator,
    between: float | None = None,
) -> None:
    """Fold candidate ``i``'s fit of motion ``m`` into its score, made on first use.

    The fit's best fitness and values, its held-out errors, why it failed if it did (named with
    the motion) and its simulations.
    """
    score = scores.setdefault(i, CandidateScore(spaces[i].model_name,
                                                spaces[i].size * len(motions), space=spaces[i]))
    score.fitness[m], score.values[m], score.held_out[m] = (fitted.fitness[0],
                                                            fitted.values[0], held)
    score.failed = score.failed or (f"{m}: {why}" if why else None)
    score.simulations += ev.simulations
    if between is not None:
        score.between[m] = between


def _screen(
    workers: Workers, spaces: Sequence[ParameterSpace],
    evs: dict[tuple[int, str], Evaluator], motions: Sequence[str], seed: int, budget: int,
    screened: Mapping[tuple[int, str], _Fitted] | None = None,
    keys: Sequence[tuple[int, str]] | None = None,
) -> tuple[dict[tuple[int, str], _Fitted], dict[int, CandidateScore]]:
    """Every candidate fitted and scored cheaply (module docstring, "The screen").

    Two stages: every (candidate, fit)'s own short search; then, every one at once, its
    restart from every other candidate's screening fit, its current and its folds. Updates
    ``evs`` with the workers' evaluators. Returns the still-water fits and the scores.
    ``keys`` (default: every one of ``evs``) are the (candidate, fit)s screened; ``screened``,
    the still-water fits of candidates screened before (those that join after the screen
    restart from them too).
    """
    keys = list(evs) if keys is None else list(keys)
    done = workers.map(_still_stage, [(evs[k], seed, SCREEN_ITERATIONS, budget) for k in keys])
    own: dict[tuple[int, str], _Fitted] = dict(screened or {})
    for k, (fitted, ev) in zip(keys, done, strict=True):
        own[k], evs[k] = fitted, ev

    def others(i: int, m: str) -> list[np.ndarray]:
        # every other candidate's fit of every motion, and this one's of the other motions: the
        # water is the same in every motion, so another motion's fit is a start too
        return [carry_over(replace(spaces[o], current=False).as_dict(own[(o, n)].values[0]),
                           spaces[i], spaces[i].bounds.mean(axis=1))
                for n in motions for o in range(len(spaces))
                if (o, n) != (i, m) and (o, n) in own]

    scored = workers.map(_screen_stage, [(evs[(i, m)], own[(i, m)], others(i, m), seed)
                                         for i, m in keys])
    still: dict[tuple[int, str], _Fitted] = {}
    scores: dict[int, CandidateScore] = {}
    for (i, m), (fits_still, fitted, (held, why), ev) in zip(keys, scored, strict=True):
        still[(i, m)], evs[(i, m)] = fits_still, ev
        _add_to_score(scores, spaces, motions, i, m, fitted, held, why and f"screen: {why}", ev)
    for i, c in scores.items():
        # every candidate's screen figures, the survivors' too (the table shows only the
        # screened-out ones'): the still-water fitness of its own search and after the restart
        # from the others' fits, the fitness with the current, and the held-out mean
        log.info("model comparison: screen: %s: %s; mean held-out error %s", c.model, "; ".join(
            f"{m} fitness {own[(i, m)].fitness[0]:.4f} own search, {still[(i, m)].fitness[0]:.4f}"
            f" restarted, {c.fitness[m]:.4f} with the current" for m in motions if m in c.fitness),
            f"{c.mean_held_out:.4f}" if np.isfinite(c.mean_held_out) else "failed")
    return still, scores


def _screen_stage(
    ev: Evaluator, own: _Fitted, others: list[np.ndarray], seed: int
) -> tuple[_Fitted, _Fitted, tuple[np.ndarray, str | None], Evaluator]:
    """A candidate's screening fit restarted from the others', with the current, and its folds."""
    still = _merge(own, multi_start_fit(ev, seed, others, SCREEN_ITERATIONS, 0)) if others \
        else own
    fitted = _with_current(ev, still, SCREEN_ITERATIONS, SCREEN_ITERATIONS)
    return still, fitted, _folds(ev, fitted, SCREEN_FOLD_ITERATIONS), ev


def _full(
    workers: Workers, spaces: Sequence[ParameterSpace],
    evs: dict[tuple[int, str], Evaluator], motions: Sequence[str], alive: Sequence[int],
    screened: Mapping[tuple[int, str], _Fitted], seed: int, iterations: int,
    fold_iterations: int, budget: int, seed_offset: int, trial: Sequence[int] = (),
    middle_budget: int = MIDDLE_BUDGET, screened_scores: Sequence[CandidateScore] = (),
) -> tuple[dict[int, CandidateScore], dict[int, CandidateScore]]:
    """The full comparison of the candidates ``alive`` (module docstring), by grid position.

    Those of them in ``trial`` first get the middle rung (:func:`_middle_stage`, its search of
    ``middle_budget`` candidates seeded as the full one), in the same barrier as the others'
    own searches; only those :func:`past_middle_rung` lets on (against ``screened_scores``, the
    screen's) then get their own searches, and join the rest. Returns the full scores and the
    scores of those stopped at the middle rung, by grid position.

    Every candidate in still water from its own starts (a search seeded ``seed + seed_offset``,
    and its screening fit where it has one), then from every other candidate's best fit so far
    carried over by name (in the grid's fixed order, and once more for any candidate whose fit
    still fails); then the ambient current from the best, and the folds. The stages are
    barriers; within one, the fits are independent and may run in worker processes: each gets
    its evaluator and gives it back with its counts, so every fit is the one the serial run
    makes.
    """
    trial = [i for i in alive if i in set(trial)]
    alive = [i for i in alive if i not in set(trial)]

    def screened_starts(i: int, m: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
        # the candidate's own screening fit (a warm start), and every other screening fit
        # carried over, of every motion (this candidate's of the other motions too) and the
        # screened-out ones' too (the best of them is polished)
        if (i, m) not in screened:
            return [], []
        others = [carry_over(replace(spaces[o], current=False).as_dict(screened[(o, n)].values[0]),
                             spaces[i], spaces[i].bounds.mean(axis=1))
                  for n in motions for o in range(len(spaces))
                  if (o, n) != (i, m) and (o, n) in screened]
        return others, [screened[(i, m)].values[0]]

    def own_searches(ks: Sequence[tuple[int, str]]) -> list[tuple[Any, ...]]:
        return [(_still_stage, (evs[k], seed + seed_offset, iterations, budget,
                                *screened_starts(*k))) for k in ks]

    # the middle rung runs beside the sure survivors' own searches, in the same barrier: where
    # it stops every candidate it tries, the comparison has no more barriers than before
    keys = [(i, m) for i in alive for m in motions]
    tried = [(i, m) for i in trial for m in motions]
    done = workers.map(_run, own_searches(keys) + [
        (_middle_stage, (evs[k], seed + seed_offset, middle_budget, *screened_starts(*k)))
        for k in tried])
    still: dict[tuple[int, str], _Fitted] = {}
    for k, (own, ev) in zip(keys, done[:len(keys)], strict=True):
        still[k], evs[k] = own, ev
    middle: dict[int, CandidateScore] = {}
    for (i, m), (fitted, (held, why), ev) in zip(tried, done[len(keys):], strict=True):
        evs[(i, m)] = ev
        _add_to_score(middle, spaces, motions, i, m, fitted, held,
                      why and f"middle rung: {why}", ev)
    going_on = past_middle_rung(middle, screened_scores, SURVIVOR_FACTOR)
    for i in trial:
        c = middle[i]
        log.info("model comparison: %s, middle rung: mean held-out error %s: %s", c.model,
                 f"{c.mean_held_out:.4f}" if np.isfinite(c.mean_held_out) else "failed",
                 "goes on to the full search" if i in going_on else "stops there")
    if going_on:
        late = [(i, m) for i in going_on for m in motions]
        for k, (own, ev) in zip(late, workers.map(_run, own_searches(late)), strict=True):
            still[k], evs[k] = own, ev
        alive = sorted(alive + going_on)
        keys = [(i, m) for i in alive for m in motions]
    middle = {i: c for i, c in middle.items() if i not in going_on}
    # the carried-over starts of a motion's candidate read the fits of the same motion's
    # candidates before it in this stage, so each motion is one task; the other motions' fits
    # of this stage's first step (every candidate's, this one's too) are starts as well
    def elsewhere(i: int, m: str) -> list[np.ndarray]:
        return [carry_over(replace(spaces[o], current=False).as_dict(still[(o, n)].values[0]),
                           spaces[i], spaces[i].bounds.mean(axis=1))
                for n in motions if n != m for o in alive]

    chains = workers.map(_cross_seed_chain, [
        ([spaces[i] for i in alive], [evs[(i, m)] for i in alive],
         [still[(i, m)] for i in alive], seed, iterations, [elsewhere(i, m) for i in alive])
        for m in motions])
    for m, (fits_m, evs_m) in zip(motions, chains, strict=True):
        for j, i in enumerate(alive):
            still[(i, m)], evs[(i, m)] = fits_m[j], evs_m[j]
    scored = workers.map(_score_stage, [(evs[k], still[k], iterations, fold_iterations)
                                        for k in keys])
    scores: dict[int, CandidateScore] = {}
    for (i, m), (fitted, (held, why), between, ev) in zip(keys, scored, strict=True):
        evs[(i, m)] = ev
        _add_to_score(scores, spaces, motions, i, m, fitted, held, why, ev, between)
    return scores, middle


def _run(task: Callable[..., Any], args: tuple[Any, ...]) -> Any:
    """``task(*args)``: lets one barrier of :class:`Workers` hold tasks of different stages."""
    return task(*args)


def _middle_stage(
    ev: Evaluator, seed: int, budget: int, extra_starts: Sequence[np.ndarray] = (),
    warm: Sequence[np.ndarray] = (),
) -> tuple[_Fitted, tuple[np.ndarray, str | None], Evaluator]:
    """A candidate's middle rung: a medium search, then its current and folds as the screen's.

    From the full search's starts (its own CMA-ES search of ``budget`` candidates, its
    screening fit, the best carried-over screening fit), each polished ``SCREEN_ITERATIONS``
    times, the current likewise, the folds ``SCREEN_FOLD_ITERATIONS`` times (module docstring,
    "The middle rung").
    """
    still = multi_start_fit(ev, seed, extra_starts, SCREEN_ITERATIONS, budget, warm)
    fitted = _with_current(ev, still, SCREEN_ITERATIONS, SCREEN_ITERATIONS)
    return fitted, _folds(ev, fitted, SCREEN_FOLD_ITERATIONS), ev


def default_jobs() -> int:
    """Worker processes of the comparison by default: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _still_stage(ev: Evaluator, seed: int, iterations: int, budget: int,
                 extra_starts: Sequence[np.ndarray] = (),
                 warm: Sequence[np.ndarray] = ()) -> tuple[_Fitted, Evaluator]:
    """A candidate's own still-water fits (first stage), and its evaluator with its counts."""
    return multi_start_fit(ev, seed, extra_starts, iterations, budget, warm), ev


def _cross_seed_chain(
    spaces: Sequence[ParameterSpace], evs: list[Evaluator], still: list[_Fitted], seed: int,
    iterations: int, elsewhere: Sequence[Sequence[np.ndarray]] = (),
) -> tuple[list[_Fitted], list[Evaluator]]:
    """One motion's candidates refitted from each other's best fits, in the grid's order.

    Candidate i starts from every other's best fit so far (those before it already refitted
    in this pass) and from ``elsewhere[i]`` (the other motions' fits, carried into its space),
    then once more for any candidate whose fit still fails.
    """
    still = list(still)

    def cross_seed(i: int) -> None:
        others = [carry_over(replace(spaces[o], current=False).as_dict(still[o].values[0]),
                             spaces[i], spaces[i].bounds.mean(axis=1))
                  for o in range(len(spaces)) if o != i]
        others += list(elsewhere[i]) if i < len(elsewhere) else []
        if others:
            again = multi_start_fit(evs[i], seed, others, iterations, 0)
            still[i] = _merge(still[i], again)

    for i in range(len(spaces)):
        cross_seed(i)
    for i in range(len(spaces)):
        if still[i].fitness[0] >= FAILED:
            cross_seed(i)
    return still, evs


def _score_stage(
    ev: Evaluator, still: _Fitted, iterations: int, fold_iterations: int
) -> tuple[_Fitted, tuple[np.ndarray, str | None], float, Evaluator]:
    """A candidate's fits with the current, folds, excursion between gaits, and evaluator.

    The excursion: :func:`~eelhost.estimation.neighbours.neighbour_excursion` of its best fit.
    """
    fitted = _with_current(ev, still, iterations)
    folds = _folds(ev, fitted, fold_iterations)
    return fitted, folds, neighbour_excursion(ev, fitted.values[0]), ev


def finalists(scores: Mapping[int, CandidateScore], count: int = FINALISTS) -> list[int]:
    """The comparison's best few: the ``count`` lowest mean held-out errors that ran, by position.

    Failed candidates are not among them (module docstring, "The finalists").
    """
    ran = sorted((i for i, c in scores.items() if np.isfinite(c.mean_held_out)),
                 key=lambda i: scores[i].mean_held_out)
    return sorted(ran[:count])


def spread_starts(space: ParameterSpace, base: np.ndarray,
                  levels: Sequence[float] = SPREAD_LEVELS,
                  steps: int = SPREAD_STEPS) -> list[np.ndarray]:
    """``base`` with its joint parameters spread over their whole bounds.

    Every combination of ``levels`` (fractions of each joint parameter's range), then each joint
    parameter alone at ``steps`` even steps from its lower to its upper bound, the others at
    ``base``'s values. The fluid coefficients (and anything after the joint parameters) stay
    ``base``'s; a space without fitted joint parameters (the paper's PD) has none. Why: where
    the joints bind, a fit whose joint parameters took up the water's misfit (a stall torque
    three times the plant's) sits in a basin that the polish from its own fit never leaves, and
    the plant's valley is narrow: on ``servo_limits`` the fitness at the plant's own turning
    coefficients is 0.11 at its stall torque 0.020 N m, 0.67 at 0.022 and 1.02 at 0.018
    (docs/estimation.md, "The finalists").

    Parameters
    ----------
    space : ParameterSpace
    base : ndarray, shape (K,)
    levels : sequence of float
    steps : int
        0: the combinations only.

    Returns
    -------
    list of ndarray, shape (K,)
        ``len(levels) ** j + j * steps`` starts for ``j`` fitted joint parameters.
    """
    k, j = len(space.coefficient_names), len(space.joints.names)
    if j == 0:
        return []
    lo, hi = space.bounds[k:k + j, 0], space.bounds[k:k + j, 1]
    grid = np.stack(np.meshgrid(*([np.asarray(levels, dtype=float)] * j), indexing="ij"), -1)
    own = (np.asarray(base, dtype=float)[k:k + j] - lo) / (hi - lo)
    lines = [np.where(np.arange(j) == p, f, own) for p in range(j)
             for f in np.linspace(0.0, 1.0, steps)] if steps > 0 else []
    out = []
    for fractions in list(grid.reshape(-1, j)) + lines:
        x = np.array(base, dtype=float)
        x[k:k + j] = lo + np.asarray(fractions) * (hi - lo)
        out.append(x)
    return out


def separated(points: np.ndarray, fitness: np.ndarray, space: ParameterSpace, count: int,
              separation: float = FINAL_SEPARATION,
              away_from: Sequence[np.ndarray] = ()) -> list[int]:
    """The best ``count`` of ``points`` by ``fitness``, each at least ``separation`` apart.

    Distances are Euclidean in the unit cube of ``space``; a point that near one already taken
    or one of ``away_from`` (the fits already polished) is passed over, and so are failed ones
    (a penalty). Indices into ``points``, best first.
    """
    u = np.clip(space.to_unit(np.atleast_2d(points)), 0.0, 1.0)
    taken_u = [np.clip(space.to_unit(np.asarray(a, float)), 0.0, 1.0) for a in away_from]
    out: list[int] = []
    for i in np.argsort(fitness, kind="stable"):
        if len(out) == count or fitness[i] >= FAILED:
            break
        if all(np.linalg.norm(u[i] - t) >= separation for t in taken_u):
            out.append(int(i))
            taken_u.append(u[i])
    return out


def _final_stage(
    ev: Evaluator, own: np.ndarray, carried: list[np.ndarray], iterations: int,
    fold_iterations: int,
) -> tuple[tuple[_Fitted, tuple[np.ndarray, str | None], float] | None, float, float,
           Evaluator]:
    """A finalist's fit refitted from more starts (module docstring, "The finalists").

    ``own``: its still-water fit; ``carried``: the other candidates' full fits (and its own of
    the other motions) carried into its space, each polished (those that run). Then its joint
    parameters spread over their bounds (:func:`spread_starts`) from its own fit and from the
    best carried one: the :data:`FINAL_POLISHED` best of those, :data:`FINAL_SEPARATION` apart
    and from the other starts, are polished too. When the best is at most :data:`IMPROVED` times its own fit's fitness,
    it is scored again (current, folds, excursion: :func:`_score_stage`). Returns that score or
    None, its own and its best refit's still-water fitness, and the evaluator.
    """
    still = replace(ev.space, current=False)
    still_ev = ev.with_space(still) if ev.space.current else ev
    first = np.array([own] + list(carried), dtype=float)[:, :still.size]
    f_first = still_ev.fitness(first)
    bases = [first[0]] + ([first[1 + int(np.argmin(f_first[1:]))]] if len(first) > 1 else [])
    spread = np.array([x for b in bases for x in spread_starts(still, b)]).reshape(-1, still.size)
    f_spread = still_ev.fitness(spread) if len(spread) else np.zeros(0)
    # every carried start that runs is polished: its fitness before the polish says little (on
    # servo_limits seed 24 the straight fit scored 1.88 on the turning gaits and polished to
    # 0.118, while the turning fit's own basin ended at 0.95); of the spread, the best few
    ran = [j for j in range(1, len(first)) if f_first[j] < FAILED]
    chosen = separated(spread, f_spread, still, FINAL_POLISHED, away_from=list(first))
    points = np.vstack([first[ran], spread[chosen]])
    best_fitness = float(f_first[0])
    out = None
    if len(points):
        results = polish_minimax_many(many_problems(still_ev, [None] * len(points)), still,
                                      points, iterations)
        ranked = sorted(results, key=lambda r: r.fitness)
        best_fitness = min(best_fitness, float(ranked[0].fitness))
        if ranked[0].fitness <= IMPROVED * f_first[0]:
            fits = _merge(_Fitted([np.asarray(r.values, float) for r in ranked],
                                  [r.fitness for r in ranked]),
                          _Fitted([first[0]], [float(f_first[0])]))
            fitted, folds, between, _ = _score_stage(ev, fits, iterations, fold_iterations)
            out = (fitted, folds, between)
    if still_ev is not ev:
        ev.count_from(still_ev)
    return out, float(f_first[0]), best_fitness, ev


def _final(
    workers: Workers, spaces: Sequence[ParameterSpace],
    evs: dict[tuple[int, str], Evaluator], full: dict[int, CandidateScore],
    iterations: int, fold_iterations: int, count: int = FINALISTS,
) -> None:
    """The finalists refitted from more starts, their scores replaced where that fit lower.

    Every fit of the :func:`finalists` is refitted in :func:`_final_stage` from every full
    candidate's fits carried over by name and from its joint parameters spread over their
    bounds; a refit at most :data:`IMPROVED` times the fit's still-water fitness replaces the
    fit and its held-out errors (unless its folds fail). ``full`` is updated in place.
    """
    keys = [(i, m) for i in finalists(full, count) for m in full[i].values]
    pool = [(o, n, spaces[o].as_dict(full[o].values[n])) for o in sorted(full)
            for n in full[o].values if not full[o].failed]
    tasks, before = [], []
    for i, m in keys:
        still = replace(spaces[i], current=False)
        own = np.asarray(full[i].values[m], dtype=float)[:still.size]
        carried = [carry_over(v, still, still.bounds.mean(axis=1))
                   for o, n, v in pool if (o, n) != (i, m)]
        before.append(evs[(i, m)].simulations)
        tasks.append((evs[(i, m)], own, carried, iterations, fold_iterations))
    done = workers.map(_final_stage, tasks)
    for (i, m), runs, (result, was, now, ev) in zip(keys, before, done, strict=True):
        evs[(i, m)] = ev
        score = full[i]
        score.simulations += ev.simulations - runs
        kept, mean = "kept", score.mean_held_out
        if result is not None and result[1][1] is None:
            fitted, (held, _), between = result
            score.fitness[m], score.values[m], score.held_out[m] = (
                fitted.fitness[0], fitted.values[0], held)
            score.between[m] = between
            kept = f"replaced; mean held-out error {mean:.4f} -> {score.mean_held_out:.4f}"
        log.info("model comparison: finalist %s, %s: still-water fitness %.4f, refit from more "
                 "starts %.4f (%s)", score.model, m, was, now, kept)


def _in_worker(job: tuple[Callable[..., Any], tuple[Any, ...]]) -> tuple[Any, int]:
    """Run one stage's task in a worker process; its result and the closed-loop runs it made."""
    task, args = job
    before = count_runs(0)
    out = task(*args)
    return out, count_runs(0) - before


def _worker_init() -> None:
    # one numba thread per worker: the workers already share the cores between them
    import numba

    numba.set_num_threads(1)


_POOLS: dict[int, ProcessPoolExecutor] = {}  # by size, kept for the next comparison


class Workers:
    """The comparison's independent fits in ``jobs`` worker processes, or in this one.

    The report runs its fits' bootstraps in them too (:mod:`eelhost.estimation.report`).
    The workers are spawned, not forked: numba's OpenMP layer cannot run in a child forked
    from a process that has used it. Spawning and loading the kernels takes seconds, so a
    pool is kept for the process's next use (the workers end with the process). Results
    come back in the order of the tasks, and every task's closed-loop runs are added to this
    process's count (progress) as it comes back.
    """

    def __init__(self, jobs: int | None, tasks: int) -> None:
        self.jobs = min(default_jobs() if jobs is None else int(jobs), tasks)
        self.pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> Workers:
        if self.jobs > 1:
            if self.jobs not in _POOLS:
                _POOLS[self.jobs] = ProcessPoolExecutor(
                    self.jobs, mp.get_context("spawn"), initializer=_worker_init)
            self.pool = _POOLS[self.jobs]
            log.info("%d worker processes", self.jobs)
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        if self.pool is not None and kind is not None:  # interrupted or broken: not kept
            _POOLS.pop(self.jobs, None)
            self.pool.shutdown(wait=False, cancel_futures=True)

    def map(self, task: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``task(*a)`` for every ``a`` of ``args``, in order."""
        if self.pool is None:
            return [task(*a) for a in args]
        out = []
        for result, runs in self.pool.map(_in_worker, [(task, a) for a in args]):
            count_runs(runs)
            out.append(result)
        return out


def _merge(a: _Fitted, b: _Fitted | None) -> _Fitted:
    """Two sets of fits as one, best first."""
    if b is None:
        return a
    pairs = sorted(zip(a.fitness + b.fitness, a.values + b.values, strict=True),
                   key=lambda p: p[0])
    return _Fitted([v for _, v in pairs], [f for f, _ in pairs])


def _one_set(
    dataset: Dataset,
    separate: CandidateScore,
    motions: list[str],
    evaluator: Callable[[ParameterSpace, list[Experiment]], Evaluator],
    seed: int,
    iterations: int,
    fold_iterations: int,
    budget: int,
) -> CandidateScore:
    """A model with one coefficient set for every motion, scored on the same held-out gaits.

    Fitted from its own starts and from the separate sets' fits; its folds hold out every
    training experiment of every motion in turn, in the order of ``motions``.
    """
    space = separate.space
    assert space is not None
    ev = evaluator(space, [e for m in motions for e in training_experiments(dataset, m)])
    own = _with_current(ev, multi_start_fit(ev, seed, [separate.values[m] for m in motions],
                                            iterations, budget), iterations)
    score = CandidateScore(f"{space.model_name}, {ONE_SET}", space.size, space=space)
    score.fitness["joint"] = own.fitness[0]
    score.values["joint"] = own.values[0]
    score.held_out["joint"], why = _folds(ev, own, fold_iterations)
    score.failed = f"joint: {why}" if why else None
    score.between["joint"] = neighbour_excursion(ev, own.values[0])
    score.simulations = ev.simulations
    return score


def _said(score: CandidateScore, say: Callable[[str], None] | None) -> None:
    text = ("failed: " + score.failed) if score.failed else (
        f"mean held-out error {score.mean_held_out:.4f}")
    if score.between and not score.failed:
        text += f", between training gaits x{score.excursion:.2f}" + (
            "" if score.sane else " (not sane)")
    if score.middle_rung:
        text = f"stopped at the middle rung ({text})"
    elif score.screened_out:
        text = f"screened out ({text})"
    log.info("%s: %s", score.model, text)
    if say:
        say(f"cross-validation: {score.model}: {text}")


def misfit_ratios(scores: Sequence[CandidateScore]) -> dict[int, dict[str, float]]:
    """Each fully fitted candidate's fitness over the lowest of its motion's, by position.

    Among the separate-set candidates that got the full search and did not fail (the screen's
    short fits and one set for every motion, fitted to other experiments, are not compared).
    A ratio above :data:`MISFIT_FACTOR` says the fit is stuck in a local minimum or its family
    cannot represent the tank (docs/estimation.md, "The finalists"); the table says so.
    """
    full = {i: c for i, c in enumerate(scores)
            if not (c.screened_out or c.failed or c.one_set)}
    best: dict[str, float] = {}
    for c in full.values():
        for m, f in c.fitness.items():
            best[m] = min(best.get(m, np.inf), f)
    return {i: {m: f / best[m] for m, f in c.fitness.items() if best[m] > 0}
            for i, c in full.items()}


def _fitness_cell(c: CandidateScore, motion: str, ratios: Mapping[str, float]) -> str:
    """A fit's fitness for the table, marked when over :data:`MISFIT_FACTOR` times the best."""
    if motion not in c.fitness:
        return "-"
    ratio = ratios.get(motion, 1.0)
    mark = f" (x{ratio:.1f} the best fit)" if ratio > MISFIT_FACTOR else ""
    return f"{c.fitness[motion]:.4f}{mark}"


def table_markdown(scores: Sequence[CandidateScore]) -> str:
    """The comparison as a markdown table, the recommended candidate marked, failures shown.

    A full fit more than :data:`MISFIT_FACTOR` times its motion's best full fit is marked with
    the ratio (:func:`misfit_ratios`).
    """
    choice = recommend(scores)
    ratios = misfit_ratios(scores)
    motions = list(dict.fromkeys(m for c in scores for m in c.fitness))
    head = ("| model | parameters | " + " | ".join(f"fitness {m}" for m in motions)
            + " | mean held-out error | worst held-out error | between training gaits"
            " | simulations |")
    lines = [head, "|---|---|" + "---|" * len(motions) + "---|---|---|---|"]
    for i, c in enumerate(scores):
        mark = (" (recommended)" if c is choice else " (stopped at the middle rung)"
                if c.middle_rung else " (screened out)" if c.screened_out else "")
        fitness = " | ".join(_fitness_cell(c, m, ratios.get(i, {})) for m in motions)
        screen = " (middle rung)" if c.middle_rung else " (screen)" if c.screened_out else ""
        held = (f"failed ({c.failed}) | failed" if c.failed
                else f"{c.mean_held_out:.4f}{screen} | {c.worst_held_out:.4f}{screen}")
        between = ("-" if not c.between else f"x{c.excursion:.2f}"
                   + ("" if c.sane else " (not sane)"))
        lines.append(f"| {c.model}{mark} | {c.parameters} | {fitness} | {held} | {between} | "
                     f"{c.simulations} |")
    return "\n".join(lines)
