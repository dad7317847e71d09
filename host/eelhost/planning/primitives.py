"""The action set: short closed-loop manoeuvres simulated with the calibrated twin (docs/model.md section 9).

A primitive is one waypoint-following manoeuvre in the robot's own frame: the robot starts at the
origin with heading 0, either straight and at rest (``REST``, the first move of a plan) or already
swimming (``SWIMMING``, every later move), and steers under its control stack to one waypoint at a
discretised distance and bearing, in a uniform current at the planning speed flowing in one of the
discretised directions relative to its heading. The primitive ends when the controller accepts the
waypoint (within the scenario's acceptance radius), which is also the moment the robot switches to
the next waypoint when a plan is executed, so primitives chain the way the robot really swims.

A ``SWIMMING`` primitive is simulated after a straight lead-in: the run's first waypoint lies
``lead_in_m`` ahead and the primitive starts at the first step where the centre of mass is inside
its acceptance circle (the true position; the controller's filtered position crosses a few
milliseconds later). Its frame is the robot's pose at that step; the waypoint is placed relative to
the lead-in waypoint and stored as it is seen from that frame, so a plan places the same waypoint
the primitive was simulated with.

For each primitive the library keeps the end pose and duration, the convex hull (scipy's Qhull) of
the link end points over the manoeuvre (the swept region), a thinned centre-of-mass path for
figures, and whether the twin completed it without a failure flag. A library is built once per
(robot, coefficients, gait, current speed, discretisation, loop options) and cached on disk under a
hash of those.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull

from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.control import Gait, wrap_angle
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT, Scenario

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

REST, SWIMMING = 0, 1

KIND_NAMES = ("rest", "swimming")
LIBRARY_VERSION = 2
"""Bump when what a library holds or how it is simulated changes: old caches then miss."""


@dataclass(frozen=True)
class Discretisation:
    """Which manoeuvres the library holds.

    Attributes
    ----------
    distances_m : tuple of float
        Distance of the waypoint from the start (rest) or from the lead-in waypoint (swimming).
    bearings_deg : tuple of float
        Bearing of the waypoint relative to the robot's heading.
    current_directions_deg : tuple of float
        Directions the current flows towards, relative to the robot's heading at the start.
    lead_in_m : float
        Straight lead-in before a swimming primitive.
    duration_s : float
        Time limit of each manoeuvre (after the lead-in); slower ones are marked failed.
    hull_stride : int
        Physics steps between the link positions that go into the hull (the robot moves about
        1 mm per step, so every 5th step loses nothing visible).
    path_points : int
        Points of the stored centre-of-mass path (for figures).
    """

    distances_m: tuple[float, ...] = (0.3, 0.45)
    bearings_deg: tuple[float, ...] = (-60.0, -30.0, 0.0, 30.0, 60.0)
    current_directions_deg: tuple[float, ...] = tuple(45.0 * k for k in range(8))
    lead_in_m: float = 0.5
    duration_s: float = 45.0
    hull_stride: int = 5
    path_points: int = 40


@dataclass
class PrimitiveLibrary:
    """Simulated primitives, one row per (kind, current direction, distance, bearing).

    Attributes
    ----------
    key : str
        Hash of everything the library depends on (see :func:`library_key`).
    discretisation : Discretisation
    current_speed_m_s : float
        Planning current speed the primitives were simulated in.
    kind : ndarray of int, shape (P,)
        ``REST`` or ``SWIMMING``.
    current_index : ndarray of int, shape (P,)
        Index into ``discretisation.current_directions_deg``.
    current_rel_deg : ndarray, shape (P,)
        The current's direction relative to the robot's heading at the primitive's start (the
        nominal direction, off by the heading the lead-in ended with).
    distance_m, bearing_deg : ndarray, shape (P,)
        The nominal waypoint.
    waypoint_rel : ndarray, shape (P, 2)
        The waypoint in the start frame, m.
    end_pose : ndarray, shape (P, 3)
        (x, y, heading) at the end in the start frame, m and rad.
    duration_s : ndarray, shape (P,)
    success : ndarray of bool, shape (P,)
        Completed within the time limit without a failure flag.
    hulls : ndarray, shape (P, H, 2)
        Convex hull of the link end points over the manoeuvre, start frame, counter-clockwise,
        padded to H by repeating the last vertex (padding does not change the polygon).
    paths : ndarray, shape (P, path_points, 2)
        Centre of mass along the manoeuvre, start frame.
    reasons : list of str
        Why a primitive failed (empty when it succeeded).
    build_time_s : float
        Wall time of the simulations and hulls.
    backend : str
        "batch" or "reference".
    body_half_width_m : float
        Largest horizontal half-axis of the links: the hulls run through the link centre lines,
        so the planner keeps this much more room.
    """

    key: str
    discretisation: Discretisation
    current_speed_m_s: float
    kind: NDArray[np.int64]
    current_index: NDArray[np.int64]
    current_rel_deg: FloatArray
    distance_m: FloatArray
    bearing_deg: FloatArray
    waypoint_rel: FloatArray
    end_pose: FloatArray
    duration_s: FloatArray
    success: NDArray[np.bool_]
    hulls: FloatArray
    paths: FloatArray
    reasons: list[str]
    build_time_s: float
    backend: str
    body_half_width_m: float
    _groups: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return int(self.kind.size)

    def group(self, kind: int, current_index: int) -> NDArray[np.int64]:
        """Indices of the successful primitives of one start kind and current direction.

        Parameters
        ----------
        kind : int
            ``REST`` or ``SWIMMING``.
        current_index : int

        Returns
        -------
        ndarray of int
        """
        key = (kind, current_index)
        if key not in self._groups:
            self._groups[key] = np.flatnonzero(
                (self.kind == kind) & (self.current_index == current_index) & self.success
            )
        return self._groups[key]

    def nearest_current_index(self, relative_deg: float, kind: int | None = None) -> int:
        """Index of the discretised current direction nearest to ``relative_deg``.

        Primitives are filed under the direction the robot actually felt at their start, and a
        cross-current lead-in can leave a direction with no swimming primitive; with ``kind``
        given, only directions holding successful primitives of that kind are considered.

        Parameters
        ----------
        relative_deg : float
            The current's direction relative to the robot's heading, deg.
        kind : int, optional
            ``REST`` or ``SWIMMING``.

        Returns
        -------
        int
            -1 when no direction holds a primitive of ``kind``.
        """
        dirs = np.asarray(self.discretisation.current_directions_deg)
        diff = np.abs(wrap_deg(relative_deg - dirs))
        if kind is not None:
            filled = np.array([self.group(kind, i).size > 0 for i in range(dirs.size)])
            if not filled.any():
                return -1
            diff = np.where(filled, diff, np.inf)
        return int(np.argmin(diff))

    def group_hulls(self, kind: int, current_index: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Hulls of :meth:`group`'s primitives, trimmed to the group's largest, with bounds.

        Parameters
        ----------
        kind : int
        current_index : int

        Returns
        -------
        hulls : ndarray, shape (M, H, 2)
            Start frame, counter-clockwise, padded by repeating the last vertex.
        centres : ndarray, shape (M, 2)
            Centre of each hull's bounding circle (mean of its vertices), start frame.
        reach : ndarray, shape (M,)
            Radius of that bounding circle.
        """
        key = ("hulls", kind, current_index)
        if key not in self._groups:
            rows = self.group(kind, current_index)
            hulls = self.hulls[rows]
            if rows.size:
                # padding repeats the last vertex: count the repeats at each hull's end
                same = np.all(hulls == hulls[:, -1:, :], axis=2)[:, ::-1]
                repeats = np.where(same.all(axis=1), same.shape[1], np.argmin(same, axis=1))
                hulls = hulls[:, : hulls.shape[1] - int(repeats.min()) + 1]
            centres = hulls.mean(axis=1)
            reach = np.linalg.norm(hulls - centres[:, None], axis=2).max(axis=1, initial=0.0)
            self._groups[key] = (hulls, centres, reach)
        return self._groups[key]

    @cached_property
    def max_progress_speed_m_s(self) -> float:
        """Largest straight-line displacement per second any successful primitive achieves.

        No plan made of these primitives gets closer to a point faster than this, which makes
        distance / this speed an admissible bound on the time left.
        """
        ok = self.success
        if not np.any(ok):
            return math.nan
        return float(np.max(np.hypot(*self.end_pose[ok, :2].T) / self.duration_s[ok]))

    # -- storage ---------------------------------------------------------------------------------

    _ARRAYS = (
        "kind", "current_index", "current_rel_deg", "distance_m", "bearing_deg", "waypoint_rel",
        "end_pose", "duration_s", "success", "hulls", "paths",
    )

    def save(self, folder: str | Path) -> Path:
        """Write ``primitives-<key>.npz`` and ``.json`` into ``folder``; return the .npz path.

        Parameters
        ----------
        folder : str or Path

        Returns
        -------
        Path
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        stem = folder / f"primitives-{self.key}"
        tmp = stem.with_suffix(f".tmp{os.getpid()}.npz")
        np.savez_compressed(tmp, **{name: getattr(self, name) for name in self._ARRAYS})
        meta = {
            "version": LIBRARY_VERSION,
            "key": self.key,
            "discretisation": dataclasses.asdict(self.discretisation),
            "current_speed_m_s": self.current_speed_m_s,
            "reasons": self.reasons,
            "build_time_s": self.build_time_s,
            "backend": self.backend,
            "body_half_width_m": self.body_half_width_m,
            "primitives": len(self),
            "successful": int(self.success.sum()),
        }
        stem.with_suffix(".json").write_text(json.dumps(meta, indent=1))
        os.replace(tmp, stem.with_suffix(".npz"))  # the .npz appears last, whole
        return stem.with_suffix(".npz")

    @classmethod
    def load(cls, folder: str | Path, key: str) -> PrimitiveLibrary | None:
        """Read a cached library, or return None when there is none for ``key``.

        Parameters
        ----------
        folder : str or Path
        key : str

        Returns
        -------
        PrimitiveLibrary or None
        """
        stem = Path(folder) / f"primitives-{key}"
        try:
            meta = json.loads(stem.with_suffix(".json").read_text())
            with np.load(stem.with_suffix(".npz")) as data:
                arrays = {name: data[name] for name in cls._ARRAYS}
        except (OSError, ValueError, KeyError):
            return None
        if meta.get("version") != LIBRARY_VERSION or meta.get("key") != key:
            return None
        disc: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                for k, v in meta["discretisation"].items()}
        return cls(
            key=key,
            discretisation=Discretisation(**disc),
            current_speed_m_s=float(meta["current_speed_m_s"]),
            reasons=list(meta["reasons"]),
            build_time_s=float(meta["build_time_s"]),
            backend=str(meta["backend"]),
            body_half_width_m=float(meta["body_half_width_m"]),
            **arrays,
        )


# -- building ------------------------------------------------------------------------------------


def library_key(
    robot: Robot,
    coefficients: FluidCoefficients,
    current_speed_m_s: float,
    discretisation: Discretisation,
    gait: Gait = PATH_GAIT,
    options: LoopOptions | None = None,
) -> str:
    """Hash of everything a library depends on (16 hex digits).

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
    current_speed_m_s : float
    discretisation : Discretisation
    gait : Gait
    options : LoopOptions, optional

    Returns
    -------
    str
    """
    payload = {
        "version": LIBRARY_VERSION,
        "robot": robot.model_dump(mode="json"),
        "coefficients": coefficients.model_dump(mode="json"),
        "current_speed_m_s": round(float(current_speed_m_s), 9),
        "discretisation": dataclasses.asdict(discretisation),
        "gait": dataclasses.asdict(gait),
        "options": dataclasses.asdict(options or LoopOptions()),
    }
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def link_endpoints(model: SwimmerModel, states: FloatArray) -> FloatArray:
    """Joint and tip positions of the robot at many states, tail tip first.

    Parameters
    ----------
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    ndarray, shape (K, N + 1, 2)
    """
    n = model.n_links
    theta = states[:, :n]
    c, s = np.cos(theta), np.sin(theta)
    g = model.geometry
    xc = states[:, n : n + 1] + c @ g.T  # link centres, as eelsim.dynamics.link_positions
    yc = states[:, n + 1 : n + 2] + s @ g.T
    lh = model.half_length_m
    x = np.concatenate([xc[:, :1] - lh[0] * c[:, :1], xc + lh * c], axis=1)
    y = np.concatenate([yc[:, :1] - lh[0] * s[:, :1], yc + lh * s], axis=1)
    return np.stack([x, y], axis=-1)


@dataclass(frozen=True)
class _Run:
    """One simulated manoeuvre: every step's state, and how it ended."""

    t_s: FloatArray
    states: FloatArray
    arrived: bool
    reason: str


def _rollouts_reference(
    robot: Robot, coefficients: FluidCoefficients, scenarios: list[Scenario], options: LoopOptions
) -> list[_Run]:
    out = []
    for s in scenarios:
        r = simulate_closed_loop(robot, s, options, seed=0, coefficients=coefficients)
        out.append(_Run(r.t_s, r.states, r.arrival_time_s is not None, r.reason))
    return out


def _rollouts_batch(
    robot: Robot,
    coefficients: FluidCoefficients,
    scenarios: list[Scenario],
    options: LoopOptions,
    threads: int | None,
) -> list[_Run]:
    from eelsim.batch import run_batch

    dt = options.timing.dt_s
    out = []
    chunk = 32  # full-state records are (runs x steps x 2N+4): chunks keep them to tens of MB
    for i in range(0, len(scenarios), chunk):
        part = scenarios[i : i + chunk]
        res = run_batch(robot, part, coefficients=coefficients, options=options, seeds=0,
                        record_full=True, threads=threads)
        full = res.full_states
        if full is None:
            raise RuntimeError("run_batch returned no full states although record_full was set")
        for r in range(len(part)):
            k = int(res.final_step[r])
            out.append(_Run(np.arange(k + 1, dtype=np.float64) * dt, full[r, : k + 1],
                            bool(np.isfinite(res.arrival_time_s[r])), res.reason(r)))
    return out


def batch_available() -> bool:
    """Whether the fast batched kernel (``eelsim.batch``) can be imported."""
    try:
        import eelsim.batch  # noqa: F401
    except Exception:  # any import-time failure means: use the reference loop
        return False
    return True


def simulate_manoeuvres(
    robot: Robot,
    coefficients: FluidCoefficients,
    scenarios: list[Scenario],
    options: LoopOptions,
    backend: str = "auto",
    threads: int | None = 1,
) -> tuple[list[_Run], str]:
    """Run closed-loop scenarios in the twin, every step recorded; the one switch of backends.

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
    scenarios : list of Scenario
    options : LoopOptions
        Must stop at the goal (a primitive ends when its waypoint is accepted).
    backend : {"auto", "batch", "reference"}
        "auto" uses ``eelsim.batch`` when it imports, else ``simulate_closed_loop``.
    threads : int or None
        Threads of the batched kernel (None: all cores).

    Returns
    -------
    runs : list
        Per scenario: times, states, arrived, failure reason.
    backend : str
        The backend used.
    """
    if backend == "auto":
        backend = "batch" if batch_available() else "reference"
    if backend == "batch":
        return _rollouts_batch(robot, coefficients, scenarios, options, threads), backend
    if backend == "reference":
        return _rollouts_reference(robot, coefficients, scenarios, options), backend
    raise ValueError(f"backend must be 'auto', 'batch' or 'reference', got {backend!r}")


def _rotate(xy: FloatArray, angle_rad: float) -> FloatArray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return xy @ np.array([[c, s], [-s, c]])


def wrap_deg(angle_deg: ArrayLike) -> FloatArray:
    """Wrap angles in degrees to (-180, 180], the convention of :func:`eelsim.control.wrap_angle`."""
    return np.degrees(wrap_angle(np.radians(angle_deg)))


def _switch_heading(run: _Run, lead_in: tuple[float, float], radius: float, n: int) -> float | None:
    """Heading when the centre of mass first enters the lead-in waypoint's circle (None: never)."""
    p = run.states[:, n : n + 2]
    inside = np.flatnonzero(np.hypot(*(p - np.asarray(lead_in)).T) < radius)
    return float(run.states[inside[0], :n].mean()) if inside.size else None


def _scenario(
    gait: Gait, waypoints: list[tuple[float, float]], speed: float, direction: float, t_max: float
) -> Scenario:
    return Scenario(
        name="primitive",
        amplitude_rad=gait.amplitude_rad,
        omega_rad_s=gait.omega_rad_s,
        beta_rad=gait.beta_rad,
        k_theta=gait.k_theta,
        waypoints_m=waypoints,
        current_speed_m_s=speed,
        current_direction_deg=direction,
        duration_s=t_max,
    )


def build_library(
    robot: Robot,
    coefficients: FluidCoefficients,
    current_speed_m_s: float,
    discretisation: Discretisation | None = None,
    gait: Gait = PATH_GAIT,
    options: LoopOptions | None = None,
    backend: str = "auto",
    threads: int | None = 1,
) -> PrimitiveLibrary:
    """Simulate every primitive of a discretisation in the twin (see the module docstring).

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
        The calibrated coefficients.
    current_speed_m_s : float
        Planning current speed.
    discretisation : Discretisation, optional
    gait : Gait
        Gait and heading gain the robot swims with (default: the paper's path gait).
    options : LoopOptions, optional
        Loop timing and camera (default: the robot's); runs always stop at the waypoint.
    backend : {"auto", "batch", "reference"}
    threads : int or None
        Threads of the batched kernel.

    Returns
    -------
    PrimitiveLibrary
    """
    disc = discretisation or Discretisation()
    opts = dataclasses.replace(options or LoopOptions(), stop_at_goal=True)
    start = time.perf_counter()
    model = SwimmerModel.from_robot(robot, coefficients)
    lead = (disc.lead_in_m, 0.0)
    rows, scenarios = [], []
    for kind in (REST, SWIMMING):
        for ci, cdir in enumerate(disc.current_directions_deg):
            for d in disc.distances_m:
                for b in disc.bearings_deg:
                    off = (d * math.cos(math.radians(b)), d * math.sin(math.radians(b)))
                    if kind == REST:
                        wps, t_max = [off], disc.duration_s
                    else:
                        wps = [lead, (lead[0] + off[0], off[1])]
                        t_max = 2.0 * disc.duration_s
                    rows.append((kind, ci, cdir, d, b, wps))
                    scenarios.append(_scenario(gait, wps, current_speed_m_s, cdir, t_max))
    runs, used = simulate_manoeuvres(robot, coefficients, scenarios, opts, backend, threads)
    n = model.n_links
    radius = scenarios[0].acceptance_radius_m
    # In a cross-current the lead-in can end with the robot turned well away from 0 deg, so the
    # current it then feels is not the nominal one. Those runs are repeated once with the current
    # turned by the heading they ended with, which brings most back into their bin; whatever
    # still lands in another bin is filed under the direction it actually felt (below).
    redo = []
    for i, (kind, _, cdir, _, _, wps) in enumerate(rows):
        if kind != SWIMMING:
            continue
        h0 = _switch_heading(runs[i], wps[0], radius, n)
        if h0 is not None and abs(wrap_deg(math.degrees(h0))) > 22.5:
            redo.append(i)
            scenarios[i] = scenarios[i].model_copy(
                update={"current_direction_deg": cdir + math.degrees(h0)}
            )
    if redo:
        again, _ = simulate_manoeuvres(
            robot, coefficients, [scenarios[i] for i in redo], opts, used, threads
        )
        for i, run in zip(redo, again, strict=True):
            runs[i] = run
    p_count = len(rows)
    out: dict[str, Any] = {
        "kind": np.zeros(p_count, dtype=np.int64),
        "current_index": np.zeros(p_count, dtype=np.int64),
        "current_rel_deg": np.full(p_count, np.nan),
        "distance_m": np.zeros(p_count),
        "bearing_deg": np.zeros(p_count),
        "waypoint_rel": np.full((p_count, 2), np.nan),
        "end_pose": np.full((p_count, 3), np.nan),
        "duration_s": np.full(p_count, np.nan),
        "success": np.zeros(p_count, dtype=bool),
        "paths": np.full((p_count, disc.path_points, 2), np.nan),
    }
    hulls: list[FloatArray] = []
    reasons: list[str] = []
    for i, ((kind, ci, _, d, b, wps), run) in enumerate(zip(rows, runs, strict=True)):
        cdir = scenarios[i].current_direction_deg
        out["kind"][i], out["current_index"][i] = kind, ci
        out["distance_m"][i], out["bearing_deg"][i] = d, b
        p = run.states[:, n : n + 2]
        k0 = 0
        if kind == SWIMMING:
            inside = np.flatnonzero(np.hypot(*(p - np.asarray(wps[0])).T) < radius)
            k0 = int(inside[0]) if inside.size else -1
        ok = run.arrived and k0 >= 0 and not run.reason
        if not ok:
            reasons.append(run.reason or "did not reach the waypoint in time")
            hulls.append(np.zeros((1, 2)))
            continue
        heading = run.states[:, :n].mean(axis=1)
        p0, h0 = p[k0], float(heading[k0])
        seg = run.states[k0:]
        picks = np.unique(np.r_[np.arange(0, len(seg), disc.hull_stride), len(seg) - 1])
        pts = _rotate(link_endpoints(model, seg[picks]).reshape(-1, 2) - p0, h0)
        hull = ConvexHull(pts)
        hulls.append(pts[hull.vertices])  # 2-D Qhull vertices are counter-clockwise
        end_xy = _rotate((p[-1] - p0)[None], h0)[0]
        out["end_pose"][i] = (end_xy[0], end_xy[1], heading[-1] - h0)
        out["waypoint_rel"][i] = _rotate((np.asarray(wps[-1]) - p0)[None], h0)[0]
        out["duration_s"][i] = run.t_s[-1] - run.t_s[k0]
        out["current_rel_deg"][i] = wrap_deg(cdir - math.degrees(h0))
        dirs = np.asarray(disc.current_directions_deg)
        out["current_index"][i] = int(np.argmin(np.abs(wrap_deg(out["current_rel_deg"][i] - dirs))))
        idx = np.linspace(0, len(seg) - 1, disc.path_points).round().astype(int)
        out["paths"][i] = _rotate(p[k0:][idx] - p0, h0)
        out["success"][i] = True
        reasons.append("")
    h_max = max(len(h) for h in hulls)
    padded = np.stack([np.concatenate([h, np.repeat(h[-1:], h_max - len(h), axis=0)])
                       for h in hulls])
    return PrimitiveLibrary(
        key=library_key(robot, coefficients, current_speed_m_s, disc, gait, opts),
        discretisation=disc,
        current_speed_m_s=float(current_speed_m_s),
        hulls=padded,
        reasons=reasons,
        build_time_s=time.perf_counter() - start,
        backend=used,
        body_half_width_m=float(model.half_axis_horizontal_m.max()),
        **out,
    )


def default_cache_dir() -> Path:
    """``$EELBOT_CACHE/primitives`` when set, else ``~/.cache/eelbot/primitives``."""
    base = os.environ.get("EELBOT_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "eelbot") / "primitives"


def load_or_build(
    robot: Robot,
    coefficients: FluidCoefficients,
    current_speed_m_s: float,
    discretisation: Discretisation | None = None,
    cache_dir: str | Path | None = None,
    gait: Gait = PATH_GAIT,
    options: LoopOptions | None = None,
    backend: str = "auto",
    threads: int | None = 1,
    rebuild: bool = False,
) -> tuple[PrimitiveLibrary, bool]:
    """The library for these inputs: from the disk cache, or built and cached.

    Parameters
    ----------
    robot, coefficients, current_speed_m_s, discretisation, gait, options, backend, threads
        As :func:`build_library`.
    cache_dir : str or Path, optional
        Default :func:`default_cache_dir`.
    rebuild : bool
        Build even when a cached library exists (and replace it).

    Returns
    -------
    library : PrimitiveLibrary
    built : bool
        True when it was simulated now, False when it came from the cache.
    """
    disc = discretisation or Discretisation()
    opts = dataclasses.replace(options or LoopOptions(), stop_at_goal=True)
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    key = library_key(robot, coefficients, current_speed_m_s, disc, gait, opts)
    if not rebuild:
        cached = PrimitiveLibrary.load(folder, key)
        if cached is not None:
            return cached, False
    log.info("no cached primitive library %s in %s: simulating it", key, folder)
    lib = build_library(robot, coefficients, current_speed_m_s, disc, gait, opts, backend, threads)
    lib.save(folder)
    return lib, True
