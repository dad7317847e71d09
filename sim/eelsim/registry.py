"""One registry style for every extension point (docs/architecture.md, "Extension points").

A :class:`Registry` holds named objects of one kind (fluid laws, joint models, guidance laws,
link transports, estimators, simulation backends, test plants, ``eelbot`` subcommands), each with
a one-line description. An object
is registered beside its definition, by a call or as a decorator (as dm_control's
``@SUITE.add``)::

    LAWS = Registry("fluid law", "eelbot.fluid_laws")

    MORISON = LAWS.add("morison", MorisonLaw(), "the paper's drag and added mass")

    @METHODS.add("cmaes", "CMA-ES with restarts")
    def fit_cmaes(problem): ...

Everything that offers a choice (the CLI's choices and help, the scripts, the parameterised tests)
reads the registry; nothing lists the names by hand. A name is registered once: a second object
under a taken name is refused (:class:`DuplicateNameError`); looking up an unknown name says the
known ones (:class:`UnknownNameError`).

Plug-ins. Another package adds its own objects through entry points, one group per registry
(``eelbot.fluid_laws``, ``eelbot.joint_models``, ``eelbot.transports``, ``eelbot.estimators``,
``eelbot.backends``, ``eelbot.plants``, ``eelbot.commands``; docs/architecture.md lists them)::

    [project.entry-points."eelbot.fluid_laws"]
    toy = "mypackage.toy:TOY_LAW"

The entry point's name is the registered name; its object is registered under it, with the
object's ``description`` attribute or the first line of its docstring, unless loading the object
already registered it (a module whose definitions carry the decorator). Plug-ins are loaded
lazily, once, on the first lookup of the registry (not when an object is added, so a plug-in may
itself import the package whose registry it extends). A plug-in that fails to load or to register
is reported, naming its entry point, through ``logging`` and :meth:`Registry.plugin_errors`; the
rest of the registry works.
"""

from __future__ import annotations

import functools
import importlib
import importlib.metadata
import logging
import pkgutil
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, replace
from types import ModuleType
from typing import Any, Generic, TypeVar

__all__ = [
    "DuplicateNameError",
    "Entry",
    "PluginError",
    "Registry",
    "RegistryError",
    "UnknownNameError",
    "check_kernel_named",
    "import_package_modules",
]

log = logging.getLogger(__name__)

T = TypeVar("T")
F = TypeVar("F")


class RegistryError(ValueError):
    """A registration or lookup a registry refuses; the message names the registry's kind."""


class DuplicateNameError(RegistryError):
    """A second object under a name already registered."""


class UnknownNameError(RegistryError, KeyError):
    """A name nothing is registered under; the message lists the known names.

    A :class:`KeyError` too, so that a registry is a :class:`~collections.abc.Mapping`.
    """

    def __str__(self) -> str:  # KeyError's would quote the whole message
        return str(self.args[0]) if self.args else ""


@dataclass(frozen=True)
class PluginError:
    """A plug-in that could not be loaded or registered.

    Attributes
    ----------
    group : str
        The entry-point group (``eelbot.fluid_laws``).
    entry_point : str
        The entry point as written: ``name = module:object``.
    error : str
        What went wrong (the exception's type and message).
    """

    group: str
    entry_point: str
    error: str

    def __str__(self) -> str:
        return f"plug-in {self.entry_point!r} ({self.group}) not loaded: {self.error}"


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered object.

    Attributes
    ----------
    name : str
    obj : object
    description : str
        One line, for help texts.
    origin : str
        ``"built-in"`` or the entry point it came from.
    """

    name: str
    obj: T
    description: str
    origin: str = "built-in"


def import_package_modules(package: str, path: Iterable[str], suffix: str = "") -> None:
    """Import every module of a package, so that its definitions register themselves.

    How a package finds its bundled objects with no list edited (the fluid laws, the joint
    models, the transports, the subcommands): called from the package's ``__init__`` with its
    ``__name__`` and ``__path__``.

    Parameters
    ----------
    package : str
        The package's dotted name.
    path : iterable of str
        Its ``__path__``.
    suffix : str, optional
        Import only the modules whose names end with it (``"_transport"``); default all.
    """
    for module in pkgutil.iter_modules(list(path)):
        if module.name.endswith(suffix):
            importlib.import_module(f"{package}.{module.name}")


def check_kernel_named(name: str, obj: object, cls: type, kind: str) -> None:
    """Refuse ``obj`` as the ``kind`` called ``name`` unless it is a ``cls`` that says that name.

    The shared part of the checks of registries whose names name generated kernel modules (fluid
    laws, joint models): the name must be an identifier and the object's ``name`` must be it.

    Raises
    ------
    ValueError
        Saying which of the three is wrong (a registry's check prefixes the kind and name).
    """
    if not isinstance(obj, cls):
        raise ValueError(f"expected a {cls.__name__}, got {type(obj).__name__}")
    if not name.isidentifier():
        raise ValueError(f"a {kind}'s name must be an identifier, got {name!r}")
    own = getattr(obj, "name", None)
    if own != name:
        raise ValueError(f"the {kind} says its name is {own!r}")


@functools.lru_cache(maxsize=4)
def _entry_points(path: tuple[str, ...]) -> dict[str, list[importlib.metadata.EntryPoint]]:
    """Every installed entry point, by group, for this ``sys.path``.

    Read once for all the registries (a scan of the installed distributions takes tens of ms);
    ``path`` is the key, so a distribution put on a new path is found.
    """
    groups: dict[str, list[importlib.metadata.EntryPoint]] = {}
    seen: set[str] = set()
    for dist in importlib.metadata.distributions():
        name = (dist.metadata["Name"] or "").lower().replace("-", "_")
        if name in seen:  # the same distribution further down the path: the first one counts
            continue
        seen.add(name)
        for ep in dist.entry_points:
            groups.setdefault(ep.group, []).append(ep)
    return groups


class Registry(Mapping[str, T]):
    """Named objects of one kind, with descriptions and entry-point plug-ins (module docstring).

    A read-only mapping from name to object, in registration order (the built-ins first, then
    the plug-ins).

    Parameters
    ----------
    kind : str
        What the objects are, for messages (``"fluid law"``).
    group : str or None
        The entry-point group plug-ins register in (``"eelbot.fluid_laws"``); None for a
        registry closed to plug-ins.
    check : callable, optional
        ``check(name, obj)`` raises :class:`ValueError` for an object that cannot be registered
        under that name (its message is kept, prefixed with the kind and name).
    builtins : callable, optional
        Called once before the first lookup, to import the modules whose definitions register
        the bundled objects (for a registry whose bundled objects live in modules nobody else
        imports, such as the subcommands).
    normalise : callable, optional
        Maps a name to its registered spelling (``str.lower`` for URI schemes).
    plural : str, optional
        What the known names are called in a failed lookup's message (default ``kind + "s"``).
    """

    def __init__(
        self,
        kind: str,
        group: str | None,
        *,
        check: Callable[[str, T], None] | None = None,
        builtins: Callable[[], object] | None = None,
        normalise: Callable[[str], str] | None = None,
        plural: str | None = None,
    ) -> None:
        self.kind = kind
        self.plural = plural or f"{kind}s"
        self.group = group
        self._check = check
        self._builtins = builtins
        self._normalise = normalise or (lambda name: name)
        self._entries: dict[str, Entry[T]] = {}
        self._loaded = False
        self._plugin_errors: list[PluginError] = []

    # ---- registering
    def add(self, name: str, obj: Any = None, description: str | None = None) -> Any:
        """Register ``obj`` under ``name``; without ``obj``, a decorator that registers its target.

        Parameters
        ----------
        name : str
        obj : object, optional
            The object. When it is a string and ``description`` is not given, it is the
            description and the call returns a decorator: ``@REG.add("name", "what it does")``.
        description : str, optional
            One line; default the object's ``description`` attribute or its docstring's first line.

        Returns
        -------
        object or callable
            The object itself (so ``X = REG.add("x", Thing(), "...")`` reads as a definition), or
            the decorator.

        Raises
        ------
        DuplicateNameError
            When another object is registered under the name.
        RegistryError
            When the registry's check refuses the object, or no description can be found.
        """
        if isinstance(obj, str) and description is None:
            description, obj = obj, None
        if obj is None:
            text = description

            def decorate(target: F) -> F:
                self.add(name, target, text)
                return target

            return decorate
        self._register(self._normalise(name), obj, description)
        return obj

    def _describe(self, name: str, obj: object, description: str | None) -> str:
        text = description
        if not (isinstance(text, str) and text.strip()):
            text = getattr(obj, "description", None)
        if not (isinstance(text, str) and text.strip()):
            # a function's, a class's, or an instance's class's docstring; not int's for 42
            plain = type(obj).__module__ == "builtins" and not callable(obj)
            doc = "" if plain else (getattr(obj, "__doc__", None) or "")
            text = doc.strip().splitlines()[0] if doc.strip() else ""
        if not text.strip():
            raise RegistryError(f"{self.kind} {name!r}: give a one-line description")
        return " ".join(text.split())

    def _register(self, name: str, obj: T, description: str | None,
                  origin: str = "built-in") -> None:
        if not isinstance(name, str) or not name:
            raise RegistryError(f"a {self.kind}'s name must be a non-empty string, got {name!r}")
        old = self._entries.get(name)
        if old is not None:
            if old.obj is obj:
                return  # the same object again (a module imported twice): nothing to do
            raise DuplicateNameError(
                f"a {self.kind} named {name!r} is already registered ({old.origin}: "
                f"{old.description}); choose another name"
            )
        if self._check is not None:
            try:
                self._check(name, obj)
            except RegistryError:
                raise
            except ValueError as err:
                raise RegistryError(f"{self.kind} {name!r}: {err}") from None
        self._entries[name] = Entry(name, obj, self._describe(name, obj, description), origin)

    def remove(self, name: str) -> None:
        """Forget ``name`` (tests that register a toy object end with this)."""
        self._entries.pop(self._normalise(name), None)

    # ---- looking up
    def _ensure_loaded(self) -> None:
        if self._loaded:
            return
        self._loaded = True  # first: a plug-in that looks the registry up while loading
        if self._builtins is not None:
            self._builtins()
        self.load_plugins()

    def load_plugins(self) -> list[PluginError]:
        """Load the plug-ins of the registry's entry-point group now (lookups do it once).

        Returns
        -------
        list of PluginError
            The plug-ins of this call that failed (each also logged as a warning).
        """
        self._loaded = True
        failed: list[PluginError] = []
        if self.group is None:
            return failed
        before = set(self._entries)  # what a plug-in's import registers is not among these
        for ep in _entry_points(tuple(sys.path)).get(self.group, ()):
            written = f"{ep.name} = {ep.value}"
            name = self._normalise(ep.name)
            if name in self._entries and self._entries[name].origin == written:
                continue
            try:
                obj = ep.load()
                own = self._entries.get(name) if name not in before else None
                if own is not None and (own.obj is obj or isinstance(obj, ModuleType)):
                    # loading it registered it (a decorator beside its definition)
                    self._entries[name] = replace(own, origin=written)
                elif isinstance(obj, ModuleType):
                    raise RegistryError(f"module {obj.__name__} registers no {self.kind} "
                                        f"named {name!r}")
                else:
                    self._register(name, obj, None, written)
            except Exception as err:  # a broken plug-in must not break the rest
                problem = PluginError(self.group, written, f"{type(err).__name__}: {err}")
                log.warning("%s", problem)
                failed.append(problem)
        self._plugin_errors.extend(failed)
        return failed

    def plugin_errors(self) -> list[PluginError]:
        """The plug-ins that failed to load so far."""
        self._ensure_loaded()
        return list(self._plugin_errors)

    def get(self, name: str, default: Any = None) -> Any:  # type: ignore[override]
        """The object under ``name``, or ``default``."""
        self._ensure_loaded()
        entry = self._entries.get(self._normalise(name))
        return default if entry is None else entry.obj

    def __getitem__(self, name: str) -> T:
        """The object under ``name``.

        Raises
        ------
        UnknownNameError
            Naming the known names.
        """
        self._ensure_loaded()
        try:
            return self._entries[self._normalise(name)].obj
        except KeyError:
            raise UnknownNameError(self.unknown_message(name)) from None

    def unknown_message(self, name: str) -> str:
        """``unknown <kind> 'x'; known <plural>: a, b, c`` (sorted): a failed lookup's message."""
        self._ensure_loaded()
        known = ", ".join(sorted(self._entries)) or "none"
        return f"unknown {self.kind} {name!r}; known {self.plural}: {known}"

    def __contains__(self, name: object) -> bool:
        self._ensure_loaded()
        return isinstance(name, str) and self._normalise(name) in self._entries

    def __iter__(self) -> Iterator[str]:
        self._ensure_loaded()
        return iter(list(self._entries))

    def __len__(self) -> int:
        self._ensure_loaded()
        return len(self._entries)

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self)

    def entry(self, name: str) -> Entry[T]:
        """The whole entry under ``name`` (object, description, origin)."""
        self._ensure_loaded()
        try:
            return self._entries[self._normalise(name)]
        except KeyError:
            raise UnknownNameError(self.unknown_message(name)) from None

    def description(self, name: str) -> str:
        """The one-line description of ``name``."""
        return self.entry(name).description

    def descriptions(self) -> dict[str, str]:
        """Every name's description, in registration order (for help texts)."""
        self._ensure_loaded()
        return {name: entry.description for name, entry in self._entries.items()}

    def registered(self) -> list[Entry[T]]:
        """The entries registered so far, without loading built-ins or plug-ins.

        For a package's own set-up code that derives objects from the ones it just registered
        (every fluid law gets a lift variant) while the package is still being imported.
        """
        return list(self._entries.values())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.group!r}: {', '.join(self._entries)})"
