"""The package's layout rules, checked on the sources of ``src/subtrace`` with :mod:`ast`
(nothing of subtrace is imported, so a broken tree still gets a full report):

* no import cycle between modules (module-level and function-local imports both count);
* the rooms (the top-level folders and modules of the package) keep the order of
  :data:`LAYERS`: a room imports only rooms below it (and itself), every import counted,
  module-level or inside a function; so the rooms' graph has no cycle either;
* no module imports another module's private (underscore) name;
* no function longer than MAX_FUNCTION_LINES, except a Numba kernel whose docstring or the
  comment just above it says why it is "not split";
* Numba is imported only through :mod:`subtrace.runtime.jit` (and
  :mod:`subtrace.runtime.numba_patches`, which jit installs);
* Numba's internals (``numba``, ``llvmlite``) are changed only in
  :mod:`subtrace.runtime.numba_patches`: no other module assigns to, or deletes, an
  attribute or item of what it imported from them, or calls ``setattr`` on it;
* importing :mod:`subtrace` or its command line executes no module that imports Numba or
  OpenImageIO at module level.

Every test lists all its violations, one per line, as ``path:line: what``.

How imports are read: a package's ``__init__`` is a module of its own (``subtrace.io``).
Relative imports are resolved against the importing module's package. ``import a.b.c``
imports the module ``a.b.c``; ``from a.b import c`` imports the module ``a.b.c`` when
``a/b/c.py`` (or ``a/b/c/__init__.py``) exists, else the module ``a.b`` (c is a name in
it); ``importlib.import_module("a.b")`` with a literal name imports ``a.b``. An import is
*module-level* when it runs at import time: anywhere outside function bodies (including
``if`` / ``try`` / ``with`` / class bodies) but not under ``if TYPE_CHECKING:``.
Executing a module also executes its parent packages' ``__init__``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PACKAGE = "subtrace"

MAX_FUNCTION_LINES = 120
NOT_SPLIT = "not split"  # the phrase that explains why a long kernel stays whole
KERNEL_DECORATORS = {"njit", "leaf_njit", "inline_njit"}
JIT_MODULE = "subtrace.runtime.jit"  # the module that imports numba for the others
PATCH_MODULE = "subtrace.runtime.numba_patches"  # the one that changes Numba's internals
NUMBA_MODULES = (JIT_MODULE, PATCH_MODULE)  # the only modules that import numba
NUMBA_ROOTS = ("numba", "llvmlite")  # whose objects only PATCH_MODULE changes
CLI_ROOTS = ("subtrace", "subtrace.cli", "subtrace.cli.__main__")
HEAVY = ("numba", "OpenImageIO")  # what importing the command line must not import

# The rooms of src/subtrace (a top-level folder, or a top-level module), lowest first, in the
# spirit of import-linter's "layers" contract: a room may import only the rooms of the layers
# below its own, and itself; rooms of one layer are siblings, which import neither each
# other. Every import counts, module-level or inside a function (a lazy import is still a
# dependency). "subtrace" is the package's own __init__, the public API at the top.
LAYERS = (
    ("version", "errors", "config", "data"),  # the base: they import nothing of ours
    ("runtime",),  # threads, Numba (jit, numba_patches), memory, signals, the atomic writer
    ("camera",),
    ("lights",),  # a light's scene keys are checked as the camera's are (check_vector)
    ("io",),  # the scene parser builds the cameras and asks lights for their keys
    ("subdiv",),  # the topology (Level, tags) and the subdivision core
    ("patches",),
    ("mesh",),  # the Cage API: its refine, limit, evaluate are subdiv's and patches' work
    ("accel",),  # the cull asks patches for shells and lights for shadow rays' reach
    # the kinds of items a ray can meet (the words every room above names them by) and each
    # kind's operations: its intersectors split patches' Bezier nets and enter boxes by
    # accel's slab tests, so the room sits above both (the patch table's own type codes are
    # patches.table.Patch, below it)
    ("geometry",),
    ("trace",),
    ("shade",),
    ("textures",),  # image textures at the hits: UVs, footprints, MIP-map lookups
    ("nurbs",),  # the NURBS pass shades its hits with shade's kernels
    ("aggregate",),  # secondary rays meet the cages (trace) and free-form surfaces (nurbs)
    ("reflect",),  # reflected rays: traced (trace, nurbs) and shaded (shade) for the picture
    ("picture",),
    ("lines",),
    ("startup",),  # the warm-up compiles trace and shade kernels; prepare, render start it
    ("tiles", "results"),  # crops and tiles (prepare checks a crop); what a render returns
    ("prepare",),
    ("render",),
    ("jobs",),
    ("cluster",),
    ("frames",),
    ("compare",),
    ("sweep",),
    ("htmlreport",),
    ("testing", "shapes"),  # the pytest plugin; small procedural cages (tests, benchmarks)
    ("cli",),
    (PACKAGE,),
)
# (importing module, imported module) -> the one-line reason it may go against LAYERS
LAYER_EXCEPTIONS: dict[tuple[str, str], str] = {}


# --------------------------------------------------------------------------------------
# reading the sources
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Import:
    """One import statement's effect: ``target`` is a module name (ours or external)."""

    line: int
    target: str
    names: tuple[str, ...]  # names taken from the target (``from target import names``)
    module_level: bool
    text: str  # the statement as written, for messages


@dataclass
class Module:
    name: str  # dotted, e.g. subtrace.io.obj; a package's __init__ is the package's name
    path: Path
    is_package: bool
    tree: ast.Module
    text: str
    imports: list[Import] = field(default_factory=list)

    @property
    def lines(self) -> list[str]:
        return self.text.splitlines()


def module_name(path: Path, src: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _resolve_relative(mod: Module, level: int, name: str | None) -> str:
    package = mod.name.split(".") if mod.is_package else mod.name.split(".")[:-1]
    base = package[: len(package) - (level - 1)] if level > 1 else package
    return ".".join(base + ([name] if name else []))


def _walk_imports(mod: Module, node: ast.AST, module_level: bool, out: list[Import]) -> None:
    """Collect the imports under ``node``; ``module_level`` is False inside function bodies
    and under ``if TYPE_CHECKING:``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            _walk_imports(mod, child, False, out)
            continue
        if isinstance(child, ast.If) and _is_type_checking(child.test):
            for stmt in child.body:
                _walk_imports(mod, ast.Module(body=[stmt], type_ignores=[]), False, out)
            for stmt in child.orelse:
                _walk_imports(mod, ast.Module(body=[stmt], type_ignores=[]), module_level, out)
            continue
        text = " ".join((ast.get_source_segment(mod.text, child) or "").split()) if isinstance(
            child, (ast.Import, ast.ImportFrom)) else None
        if isinstance(child, ast.Import):
            for alias in child.names:
                out.append(Import(child.lineno, alias.name, (), module_level, text or ""))
        elif isinstance(child, ast.ImportFrom):
            target = (_resolve_relative(mod, child.level, child.module) if child.level
                      else child.module or "")
            names = tuple(a.name for a in child.names)
            out.append(Import(child.lineno, target, names, module_level, text or ""))
        elif (isinstance(child, ast.Call) and isinstance(child.func, ast.Attribute)
              and child.func.attr == "import_module"
              and isinstance(child.func.value, ast.Name) and child.func.value.id == "importlib"
              and child.args and isinstance(child.args[0], ast.Constant)
              and isinstance(child.args[0].value, str)):
            out.append(Import(child.lineno, child.args[0].value, (), module_level,
                              f'importlib.import_module("{child.args[0].value}")'))
        _walk_imports(mod, child, module_level, out)


def load_modules(src: Path = SRC, package: str = PACKAGE) -> dict[str, Module]:
    """Every module of ``src/<package>``, parsed, with its imports."""
    modules = {}
    for path in sorted((src / package).rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        name, is_package = module_name(path, src)
        text = path.read_text(encoding="utf-8")
        mod = Module(name, path, is_package, ast.parse(text, filename=str(path)), text)
        _walk_imports(mod, mod.tree, True, mod.imports)
        modules[name] = mod
    return modules


def edges(imp: Import, modules: dict[str, Module]) -> list[str]:
    """Our modules that ``imp`` names (the submodule rule of the module docstring)."""
    out = []
    if imp.names:
        subs = [f"{imp.target}.{n}" for n in imp.names if f"{imp.target}.{n}" in modules]
        out.extend(subs)
        if len(subs) < len(imp.names) and imp.target in modules:
            out.append(imp.target)  # at least one plain name taken from the module itself
    elif imp.target in modules:
        out.append(imp.target)
    return out


def executed(name: str, modules: dict[str, Module]) -> list[str]:
    """The modules that executing ``name`` runs first: its parent packages, then itself."""
    parts = name.split(".")
    return [p for p in (".".join(parts[: k + 1]) for k in range(len(parts))) if p in modules]


def rel(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def where(mod: Module, line: int) -> str:
    return f"{rel(mod.path)}:{line}"


# --------------------------------------------------------------------------------------
# the checks (each returns its violations as lines of text)
# --------------------------------------------------------------------------------------

def _components(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``graph`` with more than one node, each
    sorted (Tarjan's algorithm, iterative: no recursion limit on deep graphs)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        m = stack.pop()
                        on_stack.discard(m)
                        component.append(m)
                        if m == node:
                            break
                    if len(component) > 1:
                        components.append(sorted(component))
    return sorted(components)


def import_cycles(modules: dict[str, Module]) -> list[str]:
    """One entry per strongly connected component of the import graph with more than one
    module: its modules, then every import between them (file:line)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for mod in modules.values():
        for imp in mod.imports:
            graph[mod.name].update(t for t in edges(imp, modules) if t != mod.name)
    components = _components(graph)
    out = []
    for component in sorted(components):
        members = set(component)
        out.append("import cycle among " + ", ".join(component) + ":")
        for name in component:
            mod = modules[name]
            for imp in mod.imports:
                for target in edges(imp, modules):
                    if target in members and target != name:
                        kind = "module level" if imp.module_level else "in a function"
                        out.append(f"    {where(mod, imp.line)}: {name} imports {target} "
                                   f"({kind}): {imp.text}")
    return out


def room(name: str) -> str:
    """The room of the module ``name``: its top-level folder or module under the package
    (``subtrace.io.obj``: io; ``subtrace.render``: render), or the package itself."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _room_imports(modules: dict[str, Module]):
    """(module, import, target module) for every import of one room by another."""
    for mod in modules.values():
        for imp in mod.imports:
            for target in edges(imp, modules):
                if room(target) != room(mod.name):
                    yield mod, imp, target


def layer_violations(modules: dict[str, Module], layers=LAYERS,
                     exceptions=LAYER_EXCEPTIONS) -> list[str]:
    """Imports against ``layers`` (lowest first; see :data:`LAYERS`): of a room of a higher
    layer, or of a sibling room of the same layer, module-level or inside a function, unless
    ``exceptions`` names the pair of modules; rooms that no layer names; and exceptions that
    no import needs any more."""
    level = {r: k for k, layer in enumerate(layers) for r in layer}
    out, used = [], set()
    for name in sorted({room(m) for m in modules} - set(level)):
        first = min((m for m in modules if room(m) == name), key=lambda m: str(modules[m].path))
        out.append(f"{rel(modules[first].path)}:1: the room {name} is in no layer "
                   f"(add it to LAYERS)")
    for mod, imp, target in _room_imports(modules):
        a, b = room(mod.name), room(target)
        if a not in level or b not in level or level[b] < level[a]:
            continue
        if (mod.name, target) in exceptions:
            used.add((mod.name, target))
            continue
        kind = "module level" if imp.module_level else "in a function"
        what = "a sibling of its layer" if level[b] == level[a] else "above it"
        out.append(f"{where(mod, imp.line)}: {mod.name} imports {target} ({kind}): the room "
                   f"{b} is {what}, {a} may import only lower rooms: {imp.text}")
    for pair in sorted(set(exceptions) - used):
        out.append(f"tests/test_layout.py:1: the layer exception {pair[0]} -> {pair[1]} is "
                   f"no longer needed: remove it")
    return sorted(set(out), key=_sort_key)


def room_cycles(modules: dict[str, Module]) -> list[str]:
    """One entry per cycle of the rooms' graph (every import counted), with the imports
    between its rooms (file:line)."""
    graph: dict[str, set[str]] = {room(m): set() for m in modules}
    for mod, _, target in _room_imports(modules):
        graph[room(mod.name)].add(room(target))
    out = []
    for component in _components(graph):
        members = set(component)
        out.append("cycle among the rooms " + ", ".join(component) + ":")
        for mod, imp, target in _room_imports(modules):
            if room(mod.name) in members and room(target) in members:
                kind = "module level" if imp.module_level else "in a function"
                out.append(f"    {where(mod, imp.line)}: {mod.name} imports {target} "
                           f"({kind}): {imp.text}")
    return out


def private_imports(modules: dict[str, Module]) -> list[str]:
    """Imports of another module's underscore name, and attribute uses of one through an
    imported module (``kernels._trace(...)`` after ``from subtrace.trace import kernels``)."""
    out = []

    def private(name: str) -> bool:
        return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))

    for mod in modules.values():
        aliases: dict[str, str] = {}  # local name -> our module it is bound to
        for node in ast.walk(mod.tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] == PACKAGE and a.asname:
                        aliases[a.asname] = a.name
            elif isinstance(node, ast.ImportFrom):
                target = (_resolve_relative(mod, node.level, node.module) if node.level
                          else node.module or "")
                for a in node.names:
                    if f"{target}.{a.name}" in modules:
                        aliases[a.asname or a.name] = f"{target}.{a.name}"
        for imp in mod.imports:
            if imp.target.split(".")[0] != PACKAGE or imp.target == mod.name:
                continue
            dotted = imp.target.split(".")[1:]
            for part in dotted:
                if private(part):
                    out.append(f"{where(mod, imp.line)}: {mod.name} imports private module "
                               f"{imp.target}: {imp.text}")
                    break
            names = [n for n in imp.names if private(n)]
            if names:
                out.append(f"{where(mod, imp.line)}: {mod.name} imports private "
                           f"name{'s' * (len(names) > 1)} {', '.join(names)} of {imp.target}")
        for node in ast.walk(mod.tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and private(node.attr)
                    and aliases[node.value.id] != mod.name):
                out.append(f"{where(mod, node.lineno)}: {mod.name} uses private name "
                           f"{node.attr} of {aliases[node.value.id]} "
                           f"({node.value.id}.{node.attr})")
    return sorted(set(out), key=_sort_key)


def _is_kernel_decorator(dec: ast.expr) -> bool:
    if isinstance(dec, ast.Call):
        dec = dec.func
    if isinstance(dec, ast.Name):
        return dec.id in KERNEL_DECORATORS
    return isinstance(dec, ast.Attribute) and dec.attr in KERNEL_DECORATORS


def _says_not_split(mod: Module, fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    doc = ast.get_docstring(fn) or ""
    if NOT_SPLIT in " ".join(doc.lower().split()):
        return True
    # the block of comment lines just above the first decorator (or the def)
    first = min([fn.lineno] + [d.lineno for d in fn.decorator_list])
    comment = []
    k = first - 2  # 0-based index of the line above
    while k >= 0 and mod.lines[k].strip().startswith("#"):
        comment.append(mod.lines[k].strip().lstrip("#").strip().lower())
        k -= 1
    return NOT_SPLIT in " ".join(" ".join(reversed(comment)).split())


def long_functions(modules: dict[str, Module]) -> list[str]:
    """Functions (methods and nested functions too) longer than MAX_FUNCTION_LINES from
    ``def`` to their last line, unless a Numba kernel that says why it is not split."""
    out = []
    for mod in modules.values():
        for node in ast.walk(mod.tree):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            length = node.end_lineno - node.lineno + 1
            if length <= MAX_FUNCTION_LINES:
                continue
            kernel = any(_is_kernel_decorator(d) for d in node.decorator_list)
            if kernel and _says_not_split(mod, node):
                continue
            why = ("a Numba kernel without a comment saying why it is not split"
                   if kernel else "not a Numba kernel")
            out.append(f"{where(mod, node.lineno)}: {mod.name}.{node.name} has {length} "
                       f"lines (> {MAX_FUNCTION_LINES}; {why})")
    return sorted(out, key=_sort_key)


def numba_imports(modules: dict[str, Module]) -> list[str]:
    """Imports of numba anywhere but in NUMBA_MODULES."""
    out = []
    for mod in modules.values():
        if mod.name in NUMBA_MODULES:
            continue
        for imp in mod.imports:
            if imp.target.split(".")[0] == "numba":
                out.append(f"{where(mod, imp.line)}: {mod.name} imports numba directly "
                           f"(use `from subtrace.runtime.jit import nb`): {imp.text}")
    return sorted(out, key=_sort_key)


def _numba_names(tree: ast.AST) -> set[str]:
    """The names that imports of NUMBA_ROOTS bind anywhere in ``tree`` (``import numba as
    nb``: nb; ``import llvmlite.binding``: llvmlite; ``from numba.core import caching``:
    caching)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in NUMBA_ROOTS:
                    names.add(alias.asname or alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module and \
                node.module.split(".")[0] in NUMBA_ROOTS:
            names.update(alias.asname or alias.name for alias in node.names)
    return names


def _root_name(node: ast.expr) -> str | None:
    """The name an attribute or item chain starts from (``a`` of ``a.b[c].d``)."""
    while isinstance(node, (ast.Attribute, ast.Subscript)):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def numba_changes(modules: dict[str, Module]) -> list[str]:
    """Changes to Numba's or llvmlite's objects anywhere but in PATCH_MODULE: an attribute
    or item of a name imported from them assigned (``=``, ``+=``, annotated), deleted, or
    set with ``setattr``."""
    out = []
    for mod in modules.values():
        if mod.name == PATCH_MODULE:
            continue
        names = _numba_names(mod.tree)
        for node in ast.walk(mod.tree):
            if isinstance(node, ast.Assign):
                targets = node.targets
            elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
                targets = [node.target]
            elif isinstance(node, ast.Delete):
                targets = node.targets
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                    node.func.id in ("setattr", "delattr") and node.args:
                targets = [ast.Attribute(value=node.args[0], attr="?")]
            else:
                continue
            flat = []
            for t in targets:
                flat.extend(t.elts if isinstance(t, (ast.Tuple, ast.List)) else [t])
            for t in flat:
                if isinstance(t, (ast.Attribute, ast.Subscript)) and _root_name(t) in names:
                    out.append(f"{where(mod, node.lineno)}: {mod.name} changes Numba's "
                               f"internals (only in {PATCH_MODULE}): "
                               f"{ast.get_source_segment(mod.text, node) or ast.dump(node)}")
    return sorted(out, key=_sort_key)


def heavy_imports_of(mod: Module) -> list[Import]:
    """``mod``'s module-level imports of numba or OpenImageIO."""
    return [imp for imp in mod.imports if imp.module_level
            and imp.target.split(".")[0] in HEAVY]


def cli_reaches_heavy(modules: dict[str, Module], roots=CLI_ROOTS) -> list[str]:
    """Follow module-level imports from ``roots``; report every executed module that is
    JIT_MODULE or imports numba or OpenImageIO at module level, with the import chain."""
    came_from: dict[str, tuple[str, Import] | None] = {}
    queue = []
    for root in roots:
        for m in executed(root, modules):
            if m not in came_from:
                came_from[m] = None
                queue.append(m)
    while queue:
        name = queue.pop(0)
        for imp in modules[name].imports:
            if not imp.module_level:
                continue
            for target in edges(imp, modules):
                for m in executed(target, modules):
                    if m not in came_from:
                        came_from[m] = (name, imp)
                        queue.append(m)

    def chain(name: str) -> str:
        steps = []
        while came_from.get(name):
            parent, imp = came_from[name]
            steps.append(f"{where(modules[parent], imp.line)} {imp.text}")
            name = parent
        return " <- ".join(steps) if steps else "(a root)"

    out = []
    for name in sorted(came_from):
        mod = modules[name]
        if name == JIT_MODULE:
            out.append(f"{rel(mod.path)}: importing the command line executes {name} "
                       f"(Numba); chain: {chain(name)}")
        for imp in heavy_imports_of(mod):
            out.append(f"{where(mod, imp.line)}: importing the command line executes {name}, "
                       f"which imports {imp.target} at module level ({imp.text}); "
                       f"chain: {chain(name)}")
    return out


def _sort_key(line: str):
    path, _, rest = line.partition(":")
    num = rest.split(":")[0]
    return (path, int(num) if num.isdigit() else 0, line)


def report(title: str, violations: list[str]) -> None:
    if violations:
        pytest.fail(f"{title} ({sum(not v.startswith(' ') for v in violations)}):\n"
                    + "\n".join(violations), pytrace=False)


# --------------------------------------------------------------------------------------
# the tests on the real tree
# --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def modules() -> dict[str, Module]:
    return load_modules()


def test_the_sources_are_found(modules):
    assert PACKAGE in modules and JIT_MODULE in modules and "subtrace.cli" in modules


def test_no_import_cycles(modules):
    report("import cycles between modules of src/subtrace", import_cycles(modules))


def test_rooms_keep_their_layers(modules):
    report("imports against the rooms' layers (tests/test_layout.py LAYERS)",
           layer_violations(modules))


def test_no_cycle_between_rooms(modules):
    report("cycles between the rooms of src/subtrace", room_cycles(modules))


KINDS_ROOM = "subtrace.geometry"  # the one room that may spell an item kind as a number


def kind_literals(modules) -> list[str]:
    """``path:line: ...`` for every comparison of an item's kind with a number (``kind[i] ==
    1``, ``x.kind[i] != 0``) and every kind column made of numbers (``kind=np.zeros(..)``,
    ``np.ones``, ``np.full(n, 3, ..)``) outside :data:`KINDS_ROOM`: kinds are named by
    ``subtrace.geometry.kinds``."""
    out = []

    def is_kind(node):  # kind[...], x.kind[...]
        node = node.value
        return (isinstance(node, ast.Name) and node.id == "kind") or (
            isinstance(node, ast.Attribute) and node.attr == "kind")

    def is_number(node):
        return isinstance(node, ast.Constant) and type(node.value) is int

    def numeric_column(node):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
            return False
        name = node.func.attr
        return name in ("zeros", "ones", "zeros_like", "ones_like") or (
            name == "full" and len(node.args) > 1 and is_number(node.args[1]))

    for mod in modules.values():
        if mod.name == KINDS_ROOM or mod.name.startswith(KINDS_ROOM + "."):
            continue
        for node in ast.walk(mod.tree):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                if any(isinstance(a, ast.Subscript) and is_kind(a) for a in sides) and any(
                        is_number(a) for a in sides):
                    out.append(f"{mod.path}:{node.lineno}: an item kind compared with a number")
            elif isinstance(node, ast.keyword) and node.arg == "kind":
                if any(numeric_column(x) for x in ast.walk(node.value)):
                    out.append(f"{mod.path}:{node.value.lineno}: a kind column of numbers")
    return out


PATCH_TYPES_MODULE = "subtrace.patches.table"  # the one that may spell a patch type as a number


def patch_type_literals(modules) -> list[str]:
    """``path:line: ...`` for every comparison of the patch table's ``patch_type`` column
    (``table.patch_type == 0``, ``patch_type[p] != 2``) with a number outside
    :data:`PATCH_TYPES_MODULE`: the types are named by ``patches.table.Patch``."""
    out = []

    def is_type(node):  # patch_type, x.patch_type, either subscripted
        if isinstance(node, ast.Subscript):
            node = node.value
        return (isinstance(node, ast.Name) and node.id == "patch_type") or (
            isinstance(node, ast.Attribute) and node.attr == "patch_type")

    for mod in modules.values():
        if mod.name == PATCH_TYPES_MODULE:
            continue
        for node in ast.walk(mod.tree):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                if any(is_type(a) for a in sides) and any(
                        isinstance(a, ast.Constant) and type(a.value) is int for a in sides):
                    out.append(f"{mod.path}:{node.lineno}: a patch type compared with a number")
    return out


def test_patch_types_are_named_not_numbered(modules):
    report("patch types spelled as numbers outside subtrace.patches.table (use "
           "patches.table.Patch)", patch_type_literals(modules))


def test_checker_finds_patch_type_literals(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "patches/__init__.py": "",
        "patches/table.py": "def f(self):\n    return self.patch_type == 0\n",
        "a.py": ("def f(table, patch_type, p, LOOP):\n"
                 "    if table.patch_type[p] == 2:\n"
                 "        pass\n"
                 "    if 1 != patch_type[p]:\n"
                 "        pass\n"
                 "    return table.patch_type == LOOP\n"),
    })
    found = patch_type_literals(mods)
    assert [line.split(":")[1] for line in found] == ["2", "4"], found


def test_item_kinds_are_named_not_numbered(modules):
    report("item kinds spelled as numbers outside subtrace.geometry (use geometry.kinds)",
           kind_literals(modules))


def test_checker_finds_kind_literals(tmp_path):
    pkg = tmp_path / "subtrace"
    (pkg / "geometry").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "geometry" / "__init__.py").write_text("")
    (pkg / "geometry" / "kinds.py").write_text("CELL = 1\nok = [k for k in [1] if k == 1]\n")
    (pkg / "a.py").write_text(
        "import numpy as np\n"
        "def f(kind, it, iso, put):\n"
        "    if kind[it] == 1:\n"
        "        pass\n"
        "    if iso.kind[it] != 0:\n"
        "        pass\n"
        "    statement = 3\n"
        "    if statement == 3:\n"
        "        pass\n"
        "    put(kind=np.r_[np.zeros(2, np.int8), np.ones(3, np.int8)][it])\n"
        "    put(kind=np.full(2, 4, np.int8))\n")
    found = kind_literals(load_modules(tmp_path))
    assert [line.split(":")[1] for line in found] == ["3", "5", "10", "11"], found


def test_no_private_names_imported(modules):
    report("underscore names of other modules used", private_imports(modules))


def test_functions_are_short(modules):
    report(f"functions over {MAX_FUNCTION_LINES} lines", long_functions(modules))


def test_numba_only_through_runtime_jit(modules):
    report("numba imported outside subtrace.runtime.jit", numba_imports(modules))


def test_numbas_internals_changed_only_in_numba_patches(modules):
    assert PATCH_MODULE in modules
    report(f"Numba's internals changed outside {PATCH_MODULE}", numba_changes(modules))


def test_checker_finds_changes_to_numba(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "runtime/__init__.py": "",
        "runtime/numba_patches.py": ("from numba.core import caching\n"
                                     "caching.CacheImpl._locator_classes = []\n"),
        "runtime/jit.py": ("import numba as _numba\nimport llvmlite.binding as ll\n"
                           "x = _numba.njit\nlocal = {}\nlocal['a'] = 1\n"
                           "def f():\n    from numba.core import config\n"
                           "    config.CACHE_DIR = 'x'\n    ll.thing, y = 1, 2\n"
                           "    setattr(_numba, 'z', 1)\n"),
        "render.py": "from numba.core.registry import cpu_target\ncpu_target.x += 1\n",
    })
    found = numba_changes(mods)
    assert [f.split(": ")[0].split("/subtrace/", 1)[1] for f in found] == [
        "render.py:2", "runtime/jit.py:8", "runtime/jit.py:9", "runtime/jit.py:10"], found


def test_cli_import_loads_no_numba(modules):
    report("modules executed by `import subtrace` / `import subtrace.cli` that bring in "
           "Numba or OpenImageIO", cli_reaches_heavy(modules))


def test_scenes_need_only_the_repository():
    """Every mesh of scenes/*.toml lies in the repository (models/), exists, and is listed
    with its licence in models/README.md: the scenes render from a plain clone."""
    import tomllib

    listed = (ROOT / "models" / "README.md").read_text(encoding="utf-8")
    bad = []
    for scene in sorted((ROOT / "scenes").glob("*.toml")):
        for obj in tomllib.loads(scene.read_text(encoding="utf-8")).get("object", []):
            mesh = (scene.parent / obj["mesh"]).resolve()
            if not mesh.is_relative_to(ROOT):
                bad.append(f"{rel(scene)}: mesh {obj['mesh']} lies outside the repository")
            elif not mesh.is_file():
                bad.append(f"{rel(scene)}: mesh {obj['mesh']} is missing")
            elif not mesh.is_relative_to(ROOT / "models"):
                bad.append(f"{rel(scene)}: mesh {obj['mesh']} is not under models/")
            elif f"`{mesh.relative_to(ROOT / 'models').as_posix()}`" not in listed:
                bad.append(f"{rel(scene)}: mesh {obj['mesh']} is not listed in models/README.md")
    report("scene meshes that a clone does not provide", bad)


# --------------------------------------------------------------------------------------
# the checker itself, on small made-up packages
# --------------------------------------------------------------------------------------

def make_package(tmp_path: Path, files: dict[str, str]) -> dict[str, Module]:
    for rel_path, text in files.items():
        path = tmp_path / PACKAGE / rel_path
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return load_modules(tmp_path, PACKAGE)


def test_checker_finds_cycles_through_submodules_and_relative_imports(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "a/__init__.py": "",
        "a/x.py": "from subtrace.b import y\n",  # y is a submodule: imports subtrace.b.y
        "b/__init__.py": "",
        "b/y.py": "def f():\n    from ..a import x\n",  # function-local, relative
        "c.py": "from subtrace.b import y\n",  # imports into the cycle, not part of it
    })
    found = import_cycles(mods)
    assert found[0] == "import cycle among subtrace.a.x, subtrace.b.y:"
    assert len(found) == 3 and "subtrace/b/y.py:2" in found[2] and "in a function" in found[2]


def test_checker_finds_imports_against_the_layers(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "base.py": "X = 1\n",
        "low/__init__.py": "",
        "low/a.py": "from subtrace import base\n",  # down: allowed
        "low/b.py": "def f():\n    from subtrace.high import c\n",  # up, in a function
        "high/__init__.py": "",
        "high/c.py": "from subtrace.low import a\nfrom subtrace import side\n",  # a sibling
        "side.py": "import subtrace.high.c\n",  # up, module level
        "stray.py": "",  # a room no layer names
    })
    layers = (("base",), ("low",), ("high", "side"), (PACKAGE,))
    found = layer_violations(mods, layers, {})
    assert [f.split(": ")[0].split("/subtrace/", 1)[1] for f in found] == [
        "high/c.py:2", "low/b.py:2", "side.py:1", "stray.py:1"], found
    assert "in a function" in found[1] and "above it" in found[1]
    assert "sibling" in found[0] and "in no layer" in found[3]
    cycles = room_cycles(mods)
    assert cycles[0] == "cycle among the rooms high, low, side:" and len(cycles) == 5, cycles
    # an exception lets one import through; one that no import needs is reported
    excused = layer_violations(mods, layers, {("subtrace.low.b", "subtrace.high.c"): "why",
                                              ("subtrace.base", "subtrace.low.a"): "stale"})
    assert not any("low/b.py" in f for f in excused)
    assert any("subtrace.base -> subtrace.low.a is no longer needed" in f for f in excused)


def test_checker_ignores_acyclic_package_imports(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "def __getattr__(n):\n    from subtrace.m import f\n    return f\n",
        "m.py": "from subtrace import config\n",  # config is a submodule, not the package
        "config.py": "X = 1\n",
    })
    assert import_cycles(mods) == []


def test_checker_finds_private_names(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "k.py": "def _f(): pass\n",
        "u.py": ("from subtrace.k import _f\nfrom subtrace import k\n"
                 "from subtrace.version import __version__\nk._f()\n"),
        "version.py": "__version__ = '1'\n",
    })
    found = private_imports(mods)
    assert len(found) == 2 and "u.py:1" in found[0] and "u.py:4" in found[1]


def test_checker_long_functions(tmp_path):
    body = "    x = 1\n" * MAX_FUNCTION_LINES
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "f.py": (f"def plain():\n{body}\n"
                 f"@nb.njit(cache=True)\ndef kernel():\n{body}\n"
                 f"# one loop over the rays: not split, so the hit record stays in registers\n"
                 f"@leaf_njit\ndef kept():\n{body}\n"
                 f"@leaf_njit\ndef kept2():\n    '''Not\n    split: one pass.'''\n{body}\n"
                 f"def short():\n    pass\n"),
    })
    found = long_functions(mods)
    assert [f.split(": ")[1].split(" ")[0] for f in found] == ["subtrace.f.plain",
                                                               "subtrace.f.kernel"]


def test_checker_follows_module_level_imports_only(tmp_path):
    mods = make_package(tmp_path, {
        "__init__.py": "",
        "cli/__init__.py": "from subtrace.cli.main import run\n",
        "cli/main.py": ("from subtrace.io import scene\n"
                        "def run():\n    from subtrace import render\n"),
        "io/__init__.py": "",
        "io/scene.py": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                        "    from subtrace.io import exr\n"),
        "io/exr.py": "import OpenImageIO as oiio\n",
        "render.py": "from subtrace.runtime.jit import nb\n",
        "runtime/__init__.py": "",
        "runtime/jit.py": "import numba as nb\n",
    })
    assert cli_reaches_heavy(mods, ("subtrace", "subtrace.cli")) == []
    assert numba_imports(mods) == []
    mods["subtrace.io.scene"].imports.append(
        Import(9, "subtrace.io", ("exr",), True, "from subtrace.io import exr"))
    found = cli_reaches_heavy(mods, ("subtrace", "subtrace.cli"))
    assert len(found) == 1 and "subtrace/io/exr.py:1" in found[0] and "OpenImageIO" in found[0]
    assert "subtrace/cli/main.py:1" in found[0] and "subtrace/io/scene.py:9" in found[0]
