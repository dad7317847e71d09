"""Every test run leaves the clone as it found it.

A test writes its outputs under its own ``tmp_path``; a command run without ``--out`` writes to
``out/`` in the working folder, and the README's lab sequence to ``lab/``. This session fixture
lists those two folders before the run and fails the run if anything new is in them afterwards,
naming the files, so a test that forgets its ``--out`` is found at once (it had left
``out/validate`` in every clone).

A second session fixture fails the run when a test compiled a batched-kernel variant that
``scripts/warm_kernels.py tests`` does not list: the test command compiles that list beforehand,
two at a time, and a variant missing from it costs 20-50 s inside a test (from a fresh clone).

It also offers the plug-in tests (of sim/ and host/) one way to install a toy package as pip
would (:func:`install_distribution`) and to have registries load their plug-ins again
(:func:`registries_afresh`).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parent
WATCHED = ("out", "lab")  # where commands write by default


def _entries() -> set[str]:
    found: set[str] = set()
    for name in WATCHED:
        folder = REPO / name
        if folder.is_dir():
            found |= {str(p.relative_to(REPO)) for p in folder.rglob("*")}
        elif folder.exists():
            found.add(name)
    return found


@pytest.fixture(scope="session", autouse=True)
def the_run_leaves_the_clone_clean():
    """Fail the run when tests left files in ``out/`` or ``lab/`` of the clone."""
    before = _entries()
    yield
    left = sorted(_entries() - before)
    if left:
        pytest.fail(f"the tests left {len(left)} paths in the clone: {', '.join(left[:6])}"
                    f"{' ...' if len(left) > 6 else ''} (write to tmp_path, give --out)",
                    pytrace=False)


@pytest.fixture(scope="session", autouse=True)
def every_kernel_the_tests_compiled_was_compiled_beforehand():
    """Fail the run when a test compiled a kernel variant that the tests' warm list lacks.

    Seen two ways: the kernels this process loaded (the loader's keys, ``eelsim.batch.loading``),
    and the kernel modules new in the kernel cache folder since the session began, which is how
    the kernels compiled in a subprocess a test starts (a comparison's worker processes, a
    command) show. Those of a fluid law or joint model a test defines itself are left out
    (``warm_kernels.unlisted``). With a cache folder shared with other work running at the same
    time, a module that work compiled meanwhile would be counted too.
    """
    from eelsim.batch.loading import kernel_cache_dir

    folder = kernel_cache_dir()
    before = {p.stem for p in folder.glob("n*_l*.py")}
    yield
    from eelsim.batch import loading

    spec = importlib.util.spec_from_file_location("warm_kernels",
                                                  REPO / "scripts" / "warm_kernels.py")
    assert spec is not None and spec.loader is not None
    warm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(warm)
    new = {p.stem for p in folder.glob("n*_l*.py")} - before
    missing = warm.unlisted(set(loading._KERNELS) | warm.module_keys(new))
    if missing:
        pytest.fail(f"tests compiled {len(missing)} kernel variants that scripts/warm_kernels.py "
                    f"tests does not list (N, lanes, stage, law, joints): {missing}; add them "
                    "there, so that the test command compiles them beforehand", pytrace=False)


InstallDistribution = Callable[..., Path]


@pytest.fixture
def install_distribution(tmp_path: Path) -> InstallDistribution:
    """``install(name, entry_points, modules=None)``: a toy distribution in ``tmp_path``, as pip.

    Writes ``<name>-0.1.dist-info`` with its ``METADATA`` and ``entry_points.txt``
    (``{group: {entry point name: "module:object"}}``) and each module ``{module name: source}``
    beside it; returns ``tmp_path``, which the test puts on ``sys.path`` (or ``PYTHONPATH``)
    for :mod:`importlib.metadata` to find it.
    """

    def install(name: str, entry_points: Mapping[str, Mapping[str, str]],
                modules: Mapping[str, str] | None = None) -> Path:
        info = tmp_path / f"{name}-0.1.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
        (info / "entry_points.txt").write_text("".join(
            f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in points.items()) + "\n"
            for group, points in entry_points.items()))
        for module, text in (modules or {}).items():
            (tmp_path / f"{module}.py").write_text(text)
        return tmp_path

    return install


@pytest.fixture
def registries_afresh(monkeypatch: pytest.MonkeyPatch) -> Callable[..., None]:
    """``afresh(*registries)``: each registry loads its plug-ins again on its next lookup.

    Its built-ins are loaded first, as in a fresh process; its entries, loaded flag and plug-in
    errors are then the test's own copies (``monkeypatch``), so what the test's plug-ins register
    is gone after it.
    """

    def afresh(*registries: Any) -> None:
        # every registry's built-ins first, as in a fresh process, before any is reset: loading
        # one's built-ins can look another up (the subcommands import the test plants, which
        # check their fluid law), which would load that one's plug-ins before the test's
        # package is on sys.path
        for registry in registries:
            registry.names()
        for registry in registries:
            monkeypatch.setattr(registry, "_entries", dict(registry._entries))
            monkeypatch.setattr(registry, "_loaded", False)
            monkeypatch.setattr(registry, "_plugin_errors", [])

    return afresh
