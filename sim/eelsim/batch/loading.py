"""Getting the compiled kernel: stage choice, kernel cache folder, module text, import.

The kernel is one Python module per (N, lanes, stage, fluid law, joint model): the driver
(``eelsim/batch/kernel_template.py``, read as text) followed by the generated part
(``eelsim.batch.codegen``) and, when the stage is compiled as C, the binding to the C library
(``eelsim.batch.c_stage``). The text is written to :func:`kernel_cache_dir` and imported from
there as ``eelsim.batch.kernels.<name>`` (the package ``eelsim.batch.kernels`` searches that
folder), where numba compiles it on first use and caches the machine code on disk beside it.

Why a file and not closures: numba's disk cache keys compiled code on a function's source file
(path and time stamp), and the driver is specialised on N and the block size (its loops over the
lanes must have constant bounds to vectorise), so each (N, lanes, ...) needs its own module
text. The file is rewritten only when its text changes, so a second process finds the cache
valid and loads in about half a second instead of compiling for a minute.

With the C stage, all the generated functions are C (``C_FUNCTIONS``) and the numba code is the
driver alone, the same for every fluid law and joint model: it is one more module,
``driver_n{N}_l{lanes}_c`` (:func:`driver_module`), compiled and cached once per (N, lanes); a C
variant's module holds its constants, its library's binding, and a ``run_blocks`` that runs the
driver with the variant's rows and function addresses (:func:`bind_driver`). A new fluid law or
joint model then costs its C compile (2-3 s), not numba's of the driver (about 30 s).
"""

from __future__ import annotations

import ctypes
import importlib
import logging
import os
import sys
import time
import warnings
from pathlib import Path
from types import ModuleType

from eelsim.batch import c_stage, codegen
from eelsim.fluid import DEFAULT_FLUID_LAW, FluidLaw, get_fluid_law
from eelsim.joints import DEFAULT_JOINT_MODEL, JointModel, get_joint_model

logger = logging.getLogger(__name__)

DEFAULT_LANES = 16
"""Runs per block (4 AVX2 vectors). Measured on the 2-core machine (docs/kernel_history.md): 8
lanes spend more of each step in the per-block driver, 32 gain nothing measurable, and longer
blocks waste more work on runs that stopped early while others in the block continue."""

STAGE_ENV = "EELSIM_STAGE"
"""Environment variable choosing how the generated stage is compiled: ``c``, ``numba`` or ``auto``."""
STAGES = ("auto", "c", "numba")
C_FUNCTIONS = ("_stage", "_screen", "_cond_bound")
"""The generated functions compiled as C when the stage is ``"c"``: all of them, so that the numba
code of a C variant is the driver alone, compiled once per (N, lanes) (:func:`driver_module`)."""
CACHE_ENV = "EELSIM_KERNEL_CACHE"
"""Environment variable naming the kernel cache folder (:func:`kernel_cache_dir`)."""
KERNELS_PACKAGE = "eelsim.batch.kernels"

_KERNELS: dict[tuple[int, int, str, str, str], ModuleType] = {}
_DRIVERS: dict[tuple[str, int, int], ModuleType] = {}  # (cache folder, N, lanes)
_LIBRARIES: dict[str, ctypes.CDLL] = {}  # the C libraries whose addresses drivers were given
_C_UNAVAILABLE: list[str] = []  # why "auto" fell back to numba (said once per process)


def stage_backend(stage: str | None = None) -> str:
    """Resolve how the generated RK4 stage is compiled: ``"c"`` or ``"numba"``.

    ``"c"``: translated to C and compiled by the machine's C compiler (``eelsim.batch.c_stage``;
    about 15 % faster here); ``"numba"``: by numba/LLVM like the rest of the kernel. ``"auto"``
    (the default, or ``$EELSIM_STAGE``) takes C when a compiler is found.

    Parameters
    ----------
    stage : str, optional
        ``"auto"``, ``"c"`` or ``"numba"``; default ``$EELSIM_STAGE`` or ``"auto"``.

    Returns
    -------
    str
        ``"c"`` or ``"numba"``.

    Raises
    ------
    ValueError
        An unknown choice (naming where it came from).
    """
    stage = _requested_stage(stage)
    if stage == "auto":
        return "c" if c_stage.find_compiler() is not None and not _C_UNAVAILABLE else "numba"
    return stage


def _requested_stage(stage: str | None) -> str:
    """The choice as given (argument, else ``$EELSIM_STAGE``, else auto), checked."""
    where = "stage"
    if stage is None:
        stage, where = os.environ.get(STAGE_ENV, "auto"), f"${STAGE_ENV}"
    if stage not in STAGES:
        raise ValueError(f"{where} must be one of {', '.join(STAGES)}; got {stage!r}")
    return stage


def kernel_cache_dir() -> Path:
    """Directory holding the generated kernel sources and numba's on-disk cache of them.

    ``$EELSIM_KERNEL_CACHE`` when set, else ``__pycache__/batch_kernels`` beside this module (git
    ignores ``__pycache__``), else ``~/.cache/eelsim/batch_kernels`` if the package is read-only.

    Returns
    -------
    Path
    """
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent / "__pycache__" / "batch_kernels"
    try:
        here.mkdir(parents=True, exist_ok=True)
        probe = here / ".writable"
        probe.touch()
        return here
    except OSError:
        return Path.home() / ".cache" / "eelsim" / "batch_kernels"


def kernel_source(n_links: int, lanes: int, stage: str = "numba",
                  law: FluidLaw | None = None, joints: JointModel | None = None) -> str:
    """The kernel module's text: the driver template with the generated part appended.

    Parameters
    ----------
    n_links, lanes : int
        N and the runs per block.
    stage : str
        ``"numba"``, or ``"c"`` to compile the generated stage as C (``eelsim.batch.c_stage``,
        raising its ``CStageError``) and append the binding that makes ``_stage`` call it.
    law : FluidLaw, optional
        The fluid law (default: the default law).
    joints : JointModel, optional
        The joint model (default: the default model).

    Returns
    -------
    str
    """
    template = (Path(__file__).parent / "kernel_template.py").read_text()
    generated = codegen.generate_stage_source(codegen.make_layout(n_links, lanes, law, joints))
    if stage == "numba":
        return template + generated
    library, symbols = c_stage.build(generated, C_FUNCTIONS, kernel_cache_dir())
    return (template + generated + c_stage.binding_source(library, symbols, generated)
            + _driver_binding(library, symbols))


def _driver_binding(library: Path, symbols: dict[str, str]) -> str:
    """Python text making a C variant's ``run_blocks`` run the shared driver with its library."""
    return "\n".join([
        "",
        "",
        "# ---- the driver: one compiled module per (N, lanes) for every fluid law and joint model",
        "# (eelsim.batch.loading.driver_module), given this library's functions by address",
        "from eelsim.batch.loading import bind_driver as _bind_driver",
        "",
        f"_DRIVER, _VARIANT = _bind_driver(globals(), {str(library)!r}, {symbols!r})",
        "",
        "",
        "def run_blocks(runs, frames, loop, outputs, threads):",
        '    """Run every block: the shared driver with this variant\'s rows and C functions."""',
        "    _DRIVER._run_blocks(runs, frames, loop, outputs, threads, _VARIANT)",
        "",
    ])


def driver_module_name(n_links: int, lanes: int) -> str:
    """The name of the driver module for N links and ``lanes`` (not of the form of a variant's).

    Parameters
    ----------
    n_links, lanes : int

    Returns
    -------
    str
    """
    return f"driver_n{n_links}_l{lanes}_c"


def driver_module(n_links: int, lanes: int) -> ModuleType:
    """The driver of every C variant with N links and ``lanes``: compiled once, cached on disk.

    Why: numba's compile of the driver is almost all of a variant's cold compile (about 28 of
    31 s; the C compiler takes about 2 s: docs/benchmarks.md, "Compile time of the batched
    kernel"), and the driver is the same code for every fluid law and joint model. Its module is
    the template with the constants of :func:`codegen.driver_constants` and calls of the
    generated functions through the addresses that each variant passes in (``variant``, see
    ``kernel_template``), so numba compiles and caches it once per (N, lanes), and one process
    runs any number of variants with it.

    Parameters
    ----------
    n_links, lanes : int
        N and the runs per block.

    Returns
    -------
    module
    """
    folder = kernel_cache_dir()
    key = (str(folder), n_links, lanes)
    if key not in _DRIVERS:
        template = (Path(__file__).parent / "kernel_template.py").read_text()
        # the generated functions' argument lists, the same for every law and model
        generated = codegen.generate_stage_source(codegen.make_layout(n_links, lanes))
        source = (template + codegen.driver_constants(n_links, lanes)
                  + c_stage.pointer_call_source(generated, C_FUNCTIONS))
        _DRIVERS[key] = load_kernel_source(driver_module_name(n_links, lanes), source)
    return _DRIVERS[key]


def bind_driver(namespace: dict[str, object], library: str,
                symbols: dict[str, str]) -> tuple[ModuleType, object]:
    """The driver module for a C variant's module and the ``variant`` array the driver runs it by.

    Called by the variant's module text (:func:`kernel_source`) as it is imported.

    Parameters
    ----------
    namespace : dict
        The variant module's globals (its constants and the template's ``_variant``).
    library : str
        The variant's C library.
    symbols : dict
        Generated function name -> C symbol, for each of :data:`C_FUNCTIONS`.

    Returns
    -------
    (module, ndarray)
        The driver module and the int64 array of ``kernel_template._variant``.

    Raises
    ------
    RuntimeError
        When a constant the driver was compiled with differs in the variant (a layout in which a
        law's or joint model's rows come before a row the driver reads).
    """
    n_links, lanes = int(namespace["N_LINKS"]), int(namespace["LANES"])  # type: ignore[call-overload]
    driver = driver_module(n_links, lanes)
    for name, value in vars(driver).items():
        if name.isupper() and name in namespace and namespace[name] != value:
            raise RuntimeError(f"the variant's {name} = {namespace[name]} differs from the "
                               f"driver's {value}: a row the driver reads moved")
    if library not in _LIBRARIES:
        _LIBRARIES[library] = ctypes.CDLL(library)
    lib = _LIBRARIES[library]
    addresses = [ctypes.cast(getattr(lib, symbols[name]), ctypes.c_void_p).value
                 for name in C_FUNCTIONS]
    make = namespace["_variant"]
    return driver, make(*addresses)  # type: ignore[operator]


def load_kernel_source(name: str, source: str) -> ModuleType:
    """Write a kernel module's text to :func:`kernel_cache_dir` and import it.

    The module is ``eelsim.batch.kernels.<name>``, importable by that name in any process that
    uses the same cache folder. The file is rewritten only when the text changed, so numba's
    cache (keyed on the file's time stamp) stays valid across processes.

    Parameters
    ----------
    name : str
        Module name within ``eelsim.batch.kernels`` (also the file's stem); an identifier.
    source : str
        The module's text.

    Returns
    -------
    module
    """
    if not name.isidentifier():
        raise ValueError(f"kernel module name must be an identifier, got {name!r}")
    folder = kernel_cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.py"
    if not path.exists() or path.read_text() != source:
        logger.info("new kernel module text %s: numba compiles it on first use", path)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(source)
        os.replace(tmp, path)  # atomic: concurrent processes never see half a file
    package = importlib.import_module(KERNELS_PACKAGE)
    if package.__path__[:1] != [str(folder)]:  # the cache folder was changed in this process
        package.__path__[:] = [str(folder)]
    importlib.invalidate_caches()  # a file written just now must be found
    full = f"{KERNELS_PACKAGE}.{name}"
    sys.modules.pop(full, None)  # run the text as it is now, even if imported before
    return importlib.import_module(full)


def kernel_module_name(n_links: int, lanes: int, stage: str, law: str, joints: str) -> str:
    """The name of a kernel variant's module and of its source file in :func:`kernel_cache_dir`.

    ``n{N}_l{lanes}_{stage}_{law}``, then ``_{joints}`` unless the joint model is the default
    (the default model's modules keep the names they had before joint models).

    Parameters
    ----------
    n_links, lanes : int
    stage, law, joints : str
        The compiled stage (``c`` or ``numba``), the fluid law's and the joint model's names.

    Returns
    -------
    str
    """
    suffix = "" if joints == DEFAULT_JOINT_MODEL else f"_{joints}"
    return f"n{n_links}_l{lanes}_{stage}_{law}{suffix}"


def kernel_module(n_links: int, lanes: int = DEFAULT_LANES, stage: str | None = None,
                  law: FluidLaw | str | None = None,
                  joints: JointModel | str | None = None) -> ModuleType:
    """Return the compiled-on-demand kernel module for N links and ``lanes`` runs per block.

    The module's source is written to :func:`kernel_cache_dir` (:func:`load_kernel_source`).

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block (a multiple of 4, so that the lane loops vectorise).
    stage : str, optional
        How the generated stage is compiled (:func:`stage_backend`). With ``"auto"`` a C
        compiler that fails is reported once as a warning and numba compiles the stage instead;
        an explicit ``"c"`` raises the compiler's error.
    law : FluidLaw or str, optional
        The fluid law (or its name); default: the default law.
    joints : JointModel or str, optional
        The joint model (or its name); default: the default model.

    Returns
    -------
    module
    """
    fluid = _law(law)
    model = _joints(joints)
    requested = _requested_stage(stage)
    chosen = stage_backend(requested)
    key = (n_links, lanes, chosen, fluid.name, model.name)
    if key in _KERNELS:
        return _KERNELS[key]
    if lanes < 4 or lanes % 4:
        raise ValueError(f"lanes must be a positive multiple of 4 (vectors), got {lanes}")
    try:
        source = kernel_source(n_links, lanes, chosen, fluid, model)
    except c_stage.CStageError as exc:
        if requested != "auto":
            raise
        _C_UNAVAILABLE.append(str(exc))
        warnings.warn(f"the batched kernel's C stage is unavailable, numba compiles it: {exc}",
                      RuntimeWarning, stacklevel=2)
        return kernel_module(n_links, lanes, "numba", fluid, model)
    module = load_kernel_source(kernel_module_name(*key), source)
    _KERNELS[key] = module
    return module


def _law(law: FluidLaw | str | None) -> FluidLaw:
    if law is None:
        return get_fluid_law(DEFAULT_FLUID_LAW)
    return get_fluid_law(law) if isinstance(law, str) else law


def _joints(joints: JointModel | str | None) -> JointModel:
    if joints is None:
        return get_joint_model(DEFAULT_JOINT_MODEL)
    return get_joint_model(joints) if isinstance(joints, str) else joints


def warm_up(
    n_links: int = 6,
    lanes: int = DEFAULT_LANES,
    stage: str | None = None,
    law: str | None = None,
    robot_file: str | None = None,
) -> float:
    """Compile (or load from the disk cache) the kernel for N links; return the seconds it took.

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.
    stage : str, optional
        How the stage is compiled (:func:`stage_backend`).
    law : str, optional
        The fluid law (default: the robot file's); the kernel depends on the law, not on its
        coefficients, so the middle of the law's bounds serves.
    robot_file : str, optional
        A bundled robot file, for its joint model (default: the paper robot's PD joints).

    Returns
    -------
    float
        Wall time of loading or compiling, s.
    """
    from eelsim.batch.api import run_batch
    from eelsim.fluid import get_fluid_law
    from eelsim.robot import load_robot
    from eelsim.scenario import load_scenario

    start = time.perf_counter()
    robot = load_robot(robot_file) if robot_file else load_robot()
    if law is not None:
        fluid = get_fluid_law(law)
        robot = robot.with_coefficients(fluid.coefficients.from_array(fluid.bounds.mean(axis=1)))
    if robot.n_links != n_links:
        robot = robot.model_copy(update={"n_links": n_links})
    scenario = load_scenario("straight").model_copy(update={"duration_s": 0.05})
    run_batch(robot, scenario, lanes=lanes, sample_steps=[0], stage=stage)
    return time.perf_counter() - start
