"""The package's shape: no import cycle, the core below everything, a short top level.

Read from the source (``ast``), so that an import inside a function or under ``TYPE_CHECKING``
counts as much as one at the top: a cycle there is still a design knot, even if Python would
import it.
"""
from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ('hac_ros', 'msg_adapters')
# what the estimation core may import besides itself: the standard library and these
CORE_THIRD_PARTY = {'numpy', 'scipy', 'yaml'}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for package in PACKAGES for p in (REPO / package).rglob('*.py')}


def _imports(path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules ``path`` imports anywhere in its source: ``from a.b import c`` is ``a.b.c``
    when that is a module, else ``a.b``; relative imports are resolved."""
    own = _module_name(path)
    package = own if path.name == '__init__.py' else own.rpartition('.')[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = package.split('.')[:len(package.split('.')) - node.level + 1]
                base = '.'.join(anchor + ([base] if base else []))
            for alias in node.names:
                found.add(f'{base}.{alias.name}' if f'{base}.{alias.name}' in modules else base)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: {m for m in _imports(path, modules) if m in modules and m != name}
            for name, path in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_module_imports_itself_back_through_others():
    graph = _graph()
    # the graph is read right: a few edges every reader of the code knows
    assert 'hac_ros.core.frame_loop' in graph['hac_ros.core.calibrator']
    assert 'hac_ros.core.calibrator' in graph['hac_ros.replay.replayer']
    assert 'msg_adapters' in graph['hac_ros.bridge.messages']
    assert _cycles(graph) == []


def _folder(module: str) -> str:
    """The folder a module lives in: ``hac_ros.core.bodies.sample`` -> ``hac_ros.core``; the
    top-level modules of hac_ros (cli entry points, api) are their own."""
    parts = module.split('.')
    return '.'.join(parts[:2]) if len(parts) > 2 or parts[0] != 'hac_ros' else module


def test_no_folder_imports_itself_back_through_others():
    """The folders (subpackages) as rooms, an arrow for any import between two of them: no
    circle, so each folder can be read knowing only the ones below it."""
    graph: dict[str, set[str]] = {}
    for module, imported in _graph().items():
        graph.setdefault(_folder(module), set()).update(
            _folder(m) for m in imported if _folder(m) != _folder(module))
    for target in {t for targets in graph.values() for t in targets}:
        graph.setdefault(target, set())
    assert 'hac_ros.core' in graph['hac_ros.replay'] and 'hac_ros.core' not in {
        t for folder, targets in graph.items() for t in targets if folder == 'hac_ros.core'}
    assert _cycles(graph) == []


# the core's rooms, lowest first (hac_ros/core/__init__.py): each imports only rooms before it
CORE_ROOMS = ('basics', 'layouts', 'rules', 'geometry', 'estimate', 'bodies', 'stream')


def _room(module: str) -> str:
    """A core module's room (``hac_ros.core.geometry.plane`` -> ``geometry``); ``top`` for the
    modules of hac_ros/core itself (the calibrator and its loop, above every room)."""
    parts = module.split('.')
    return parts[2] if len(parts) > 3 or (len(parts) == 3 and parts[2] in CORE_ROOMS) else 'top'


def _room_arrows() -> set[tuple[str, str]]:
    return {(_room(module), _room(m)) for module, imported in _graph().items()
            if module.startswith('hac_ros.core.') for m in imported
            if m.startswith('hac_ros.core.') and _room(m) != _room(module)}


def test_the_core_rooms_import_only_rooms_below_them():
    """hac_ros/core in rooms, read from the bottom: each room imports only the rooms before it
    in CORE_ROOMS, and none imports the calibrator's modules above them (no arrow up, so no
    circle). Every subpackage of the core is a room of the list."""
    rooms = {p.name for p in (REPO / 'hac_ros' / 'core').iterdir()
             if (p / '__init__.py').is_file()}
    assert rooms == set(CORE_ROOMS)
    order = {room: k for k, room in enumerate(CORE_ROOMS + ('top',))}
    arrows = _room_arrows()
    assert ('top', 'stream') in arrows and ('bodies', 'geometry') in arrows  # read right
    assert [(a, b) for a, b in sorted(arrows) if order[b] > order[a]] == []


def test_the_cycle_finder_finds_a_cycle():
    """The check above can fail: a two-module and a three-module knot are both reported."""
    graph = {'a': {'b'}, 'b': {'a'}, 'c': {'d'}, 'd': {'e'}, 'e': {'c'}, 'f': {'a'}}
    assert sorted(_cycles(graph)) == [['a', 'b'], ['c', 'd', 'e']]


def test_the_core_imports_only_the_core_numpy_and_scipy():
    """hac_ros.core is the bottom layer: pure numpy/scipy, nothing from the shells or ROS."""
    modules = _modules()
    stdlib = {'__future__', 'bisect', 'collections', 'dataclasses', 'enum', 'functools', 'itertools',
              'math', 'pathlib', 'typing', 'abc', 'importlib', 'pkgutil'}
    for name, path in modules.items():
        if not name.startswith('hac_ros.core'):
            continue
        for imported in _imports(path, modules):
            top = imported.split('.')[0]
            assert imported.startswith('hac_ros.core') or top in CORE_THIRD_PARTY | stdlib, \
                f'{name} imports {imported}'


def test_the_top_level_of_the_package_stays_short():
    """At most 8 modules beside the subpackages: a newcomer finds things by the folder names."""
    top = sorted(p.name for p in (REPO / 'hac_ros').glob('*.py'))
    assert len(top) <= 8, top


def test_only_the_command_draws_progress_bars():
    """The library logs and advances the progress display its caller gives; tqdm (a terminal's
    bar) is imported in hac_ros.cli only."""
    modules = _modules()
    drawing = sorted(name for name, path in modules.items()
                     if not name.startswith('hac_ros.cli')
                     and any(m == 'tqdm' or m.startswith('tqdm.') for m in _imports(path, modules)))
    assert drawing == []


# -------------------------------------------------------------- MediaPipe stays in hac_ros.people
PEOPLE_ONLY = {'mediapipe', 'cv2'}  # the [people] extra's libraries


def _reachable(graph: dict[str, set[str]], roots: list[str]) -> set[str]:
    seen: set[str] = set()
    todo = [r for r in roots if r in graph]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo += sorted(graph[name] - seen)
    return seen


def test_only_the_people_front_end_imports_mediapipe_and_opencv():
    """MediaPipe and OpenCV (the [people] extra) are imported by hac_ros.people's model only,
    or through hac_ros.people.extra (which imports them by name, for a clear message when they
    are missing); the core, the replay and hac_node reach neither, through any chain of
    imports."""
    modules = _modules()
    importers = sorted(name for name, path in modules.items()
                       if any(m.split('.')[0] in PEOPLE_ONLY for m in _imports(path, modules)))
    assert importers == ['hac_ros.people.model']
    gate_users = sorted(name for name, path in modules.items()
                        if 'hac_ros.people.extra' in _imports(path, modules))
    assert gate_users and all(n.startswith(('hac_ros.people.', 'hac_ros.cli.people',
                                            'hac_ros.ros.people_node', 'hac_ros.video.',
                                            'hac_ros.cli.video'))
                              for n in gate_users), gate_users
    graph = _graph()
    roots = [n for n in graph if n.startswith(('hac_ros.core', 'hac_ros.replay'))]
    reached = _reachable(graph, [*roots, 'hac_ros.ros.node', 'hac_ros.ros.lifecycle_node',
                                 'hac_ros.api', 'hac_ros.files.importer'])
    assert 'hac_ros.ros.node' in reached and 'hac_ros.core.calibrator' in reached
    assert not reached & {'hac_ros.people.extra', 'hac_ros.people.images',
                          'hac_ros.people.model', 'hac_ros.ros.people_node'}


def test_only_the_video_extra_imports_pycolmap():
    """pycolmap (the [video] extra) is imported by hac_ros.video.extra alone, by name (a clear
    message when it is missing), and used through it by hac_ros.video's modules only; nothing
    but hac video's own modules and command reach hac_ros.video."""
    modules = _modules()
    importers = sorted(name for name, path in modules.items()
                       if any(m.split('.')[0] == 'pycolmap' for m in _imports(path, modules)))
    assert importers == []
    by_name = sorted(name for name, path in modules.items()
                     if "import_module('pycolmap')" in path.read_text(encoding='utf-8'))
    assert by_name == ['hac_ros.video.extra']
    gate_users = sorted(name for name, path in modules.items()
                        if 'hac_ros.video.extra' in _imports(path, modules))
    assert gate_users and all(n.startswith(('hac_ros.video.', 'hac_ros.cli.video'))
                              for n in gate_users), gate_users
    graph = _graph()
    outside = [n for n in graph if not n.startswith(('hac_ros.video', 'hac_ros.cli'))]
    assert not {n for n in _reachable(graph, outside) if n.startswith('hac_ros.video')}


def test_hac_node_and_the_replay_run_without_importing_mediapipe():
    """The real thing: a process that imports hac_node, the replay and calibrate() and calibrates
    a simulated scene has neither MediaPipe nor OpenCV loaded."""
    import subprocess
    import sys

    code = ('import sys\n'
            'import hac_ros.ros.node, hac_ros.replay.replayer, hac_ros.cli.replay\n'
            'from hac_ros.simulate import make_scenario\n'
            'from hac_ros.core.calibrator import Calibrator\n'
            'from hac_ros.core.rules.params import HacParams\n'
            'from hac_ros.simulate.feed import feed_events, scenario_events\n'
            "sc = make_scenario('walk', seed=1, duration=3.0, joint_layout='blazepose33')\n"
            "cal = Calibrator(HacParams().replace(joint_layout='blazepose33'))\n"
            'out = feed_events(cal, scenario_events(sc))\n'
            "print(len(out), sorted(m for m in ('mediapipe', 'cv2') if m in sys.modules))\n")
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         cwd=REPO, timeout=300)
    assert run.returncode == 0, run.stderr
    count, loaded = run.stdout.split(' ', 1)
    assert int(count) > 0 and loaded.strip() == '[]', run.stdout
