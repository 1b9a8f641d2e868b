"""The method registry: one record per TAN method, read by everything that names methods.

A :class:`MethodRecord` says what a method is (name, one-line summary, the states it
estimates, the series it adds), how to seed it (a stable ``seed_id``), what it costs
(for ``tanbench plan``), how to draw it, which options it takes, and how to run it.

Methods come from three places, looked up in this order:

1. the built-ins, one module each in :data:`BUILTIN_MODULES` (a module registers its
   records with :func:`register` when imported);
2. installed packages' entry points in the group ``tanbench.methods``: the entry point's
   name is the method name, its value a ``MethodRecord`` or a run function;
3. a sweep's ``methods:`` entry ``package.module:function`` (or ``:RECORD``): imported
   on first use, in the parent and in every worker.

A stored run is reused only if it was made by the same code (:meth:`MethodRecord.code_id`):
the built-ins' identity is :data:`tanbench.config.MODEL_VERSION` in every cell key; a
user method's is the ``version`` its record declares or, without one, a hash of the
Python sources of its package (of its module, when it is not in a package).
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

from tanbench.config import format_validation_error
from tanbench.errors import TanbenchError

# the built-in methods: adding one is one new module plus its line here
BUILTIN_MODULES = ("tanbench.methods.tight", "tanbench.methods.loose", "tanbench.methods.pmf", "tanbench.methods.mpf",
                   "tanbench.methods.ekf", "tanbench.methods.tercom", "tanbench.methods.multibeam")
ENTRY_POINT_GROUP = "tanbench.methods"
_IMPORT_NAME = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")

_REGISTRY: dict[str, "MethodRecord"] = {}
_builtins_loaded = False


def particle_steps(scenario) -> float:
    """The default cost unit: particles x updates."""
    return scenario.particles * scenario.planned_duration_s / scenario.sampling_time_s


@dataclass(frozen=True)
class MethodRecord:
    """One registered method (see the module docstring)."""

    name: str
    seed_id: int  # enters the method's filter seed: never change it once results exist
    summary: str
    run: Callable
    states: tuple[str, ...] = ("east", "north")
    series: tuple[str, ...] = ()  # extra series (beyond the scored ones) the method returns
    options: type | None = None  # a pydantic model of the method's own options
    cost_ns: float = 100.0  # single-core ns per cost unit (plan's estimate)
    cost_units: Callable = particle_steps  # scenario -> number of cost units of one run
    color: str | None = None
    linestyle: str = "-"
    builtin: bool = False
    # its posterior Cramer-Rao bound (bounds.pcrb): (sensor "dvl" or "sbe", states "full" or "position");
    # None: no bound is computed for the method
    bound: tuple[str, str] | None = None
    # a user method's declared code version: change it whenever the method's results would change
    # (None: its package's source is its identity, and any edit of it recomputes its stored runs)
    version: str | None = None

    def estimate_seconds(self, scenario) -> float:
        return self.cost_ns * 1e-9 * float(self.cost_units(scenario))

    def code_id(self) -> str | None:
        """What identifies the code that makes this method's results (None for a built-in, whose
        identity is MODEL_VERSION in the cell key): ``version <v>`` or ``source <hash>``."""
        if self.builtin:
            return None
        if self.version is not None:
            return f"version {self.version}"
        module = inspect.getmodule(self.run)
        return f"source {source_hash(module.__name__ if module is not None else '')}"

    def parse_options(self, scenario):
        """The method's validated options from ``scenario.method_options[name]`` (None without a model)."""
        given = (scenario.method_options or {}).get(self.name, {})
        if self.options is None:
            if given:
                raise TanbenchError(f"method_options.{self.name}: method {self.name!r} takes no options")
            return None
        from pydantic import ValidationError

        unknown = sorted(set(given) - set(self.options.model_fields))
        if unknown:
            raise TanbenchError(f"method_options.{self.name}.{unknown[0]}: unknown option of {self.name!r} "
                                f"(known: {', '.join(self.options.model_fields)})")
        try:
            return self.options(**given)
        except ValidationError as exc:
            raise TanbenchError(format_validation_error(exc, f"method_options.{self.name}.")) from None


def register(record: MethodRecord) -> MethodRecord:
    """Add a method; a second record with the same name or seed id is an error."""
    if record.name in _REGISTRY and _REGISTRY[record.name] is not record:
        raise TanbenchError(f"method {record.name!r} is registered twice")
    for other in _REGISTRY.values():
        if other.seed_id == record.seed_id and other.name != record.name:
            raise TanbenchError(f"methods {other.name!r} and {record.name!r} share seed id {record.seed_id}")
    _REGISTRY[record.name] = record
    return record


def _load_builtins() -> None:
    global _builtins_loaded
    if _builtins_loaded:
        return
    _builtins_loaded = True
    for module in BUILTIN_MODULES:
        importlib.import_module(module)


def names() -> tuple[str, ...]:
    """The built-in and installed methods' names: the built-ins by seed id, then the others in
    registration order."""
    _load_builtins()
    _load_entry_points()
    return builtin_names() + tuple(n for n, r in _REGISTRY.items() if not r.builtin)


def builtin_names() -> tuple[str, ...]:
    """The built-in methods' names in a fixed order, by seed id: never the order their modules
    happened to be imported in (a test that imported ``tanbench.methods.mpf`` first once put
    mpf-dvl at the front, and every index taken from this tuple moved with it)."""
    _load_builtins()
    return tuple(sorted((n for n, r in _REGISTRY.items() if r.builtin), key=lambda n: _REGISTRY[n].seed_id))


_entry_points_loaded = False


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in _REGISTRY:
            try:
                obj = ep.load()
            except Exception as exc:  # noqa: BLE001 - a broken plug-in package is one line, not a crash
                raise TanbenchError(f"method {ep.name!r} (entry point {ep.value}) does not load: "
                                    f"{type(exc).__name__}: {exc}") from None
            register(_as_record(ep.name, obj, ep.value))


def get(name: str) -> MethodRecord:
    """The record of method ``name``: a registered name or ``package.module:function``."""
    _load_builtins()
    if name in _REGISTRY:
        return _REGISTRY[name]
    if _IMPORT_NAME.match(name):
        return register(_import_method(name))
    _load_entry_points()
    if name in _REGISTRY:
        return _REGISTRY[name]
    raise TanbenchError(f"unknown method {name!r}; known: {', '.join(names())} "
                        f"(or a user method as package.module:function)")


def _import_method(name: str) -> MethodRecord:
    module_name, attr = name.split(":", 1)
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise TanbenchError(f"method {name!r}: module {exc.name!r} not found (is it on PYTHONPATH, "
                            f"or installed?)") from None
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - the user's module failed (or called sys.exit) while importing
        raise TanbenchError(f"method {name!r}: importing {module_name} failed: {type(exc).__name__}: {exc}") from None
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise TanbenchError(f"method {name!r}: {module_name} has no attribute {attr!r}")
        obj = getattr(obj, part)
    return _as_record(name, obj, name)


LINESTYLES = ("-", "--", "-.", ":")  # what the figures draw a method's lines with (MethodRecord.linestyle)


def check_plot_style(name: str, record: MethodRecord) -> None:
    """Refuse a record whose plot style the figures cannot draw, when it is loaded (not later, in ``plot``)."""
    if record.linestyle not in LINESTYLES:
        raise TanbenchError(f"method {name!r}: linestyle {record.linestyle!r} is not one of {', '.join(LINESTYLES)}")
    if record.color is None:
        return
    try:
        from matplotlib.colors import is_color_like
    except ImportError:  # no figures without matplotlib: nothing to check the colour for
        return
    if not is_color_like(record.color):
        raise TanbenchError(f"method {name!r}: color {record.color!r} is not a matplotlib colour "
                            f"(e.g. 'tab:pink' or '#1f77b4')")


def _as_record(name: str, obj, source: str) -> MethodRecord:
    """A user's object as a record: a MethodRecord (renamed to ``name``) or a run function."""
    import dataclasses

    if isinstance(obj, MethodRecord):
        check_plot_style(name, obj)
        return dataclasses.replace(obj, name=name, seed_id=user_seed_id(name), builtin=False)
    if not callable(obj):
        raise TanbenchError(f"method {name!r}: {source} is a {type(obj).__name__}, not a function or MethodRecord")
    doc = (getattr(obj, "__doc__", None) or "").strip().splitlines()
    return MethodRecord(name=name, seed_id=user_seed_id(name), summary=doc[0] if doc else f"user method {source}",
                        run=obj)


@lru_cache(maxsize=None)
def source_hash(module_name: str) -> str:
    """A 16-hex-digit hash of the Python sources of a user module's top-level package (every
    ``.py`` below it, by relative path), or of the module's own file outside a package."""
    module = sys.modules.get(module_name)
    path = getattr(module, "__file__", None)
    if path is None:
        return "unknown"
    # the outermost regular package holding the module (its run may be in that package's __init__.py; above it
    # may be a namespace package, which has no file of its own), else the module's own file
    parts = module_name.split(".")
    packages = (getattr(sys.modules.get(".".join(parts[:i])), "__file__", None) for i in range(1, len(parts) + 1))
    package = next((Path(f) for f in packages if f is not None and Path(f).name == "__init__.py"), None)
    if package is not None:
        root = package.parent
        files = sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)
    else:
        root, files = Path(path).parent, [Path(path)]
    digest = hashlib.sha256()
    for file in files:
        digest.update(file.relative_to(root).as_posix().encode() + b"\0" + file.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def user_seed_id(name: str) -> int:
    """A stable seed id for a user method, from its name (above the built-ins' small ids)."""
    return (1 << 32) + int(hashlib.sha256(name.encode()).hexdigest()[:8], 16)
