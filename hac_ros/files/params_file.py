"""The parameters file, read as ROS 2 reads it: one reader for ``hac_node`` and every command.

A ROS 2 parameters file maps node names to ``ros__parameters`` (docs/interface.md, "Parameters")::

    /**:                       # every node: use_sim_time and the like
      ros__parameters: {use_sim_time: true}
    hac_node:                  # this node in the root namespace (also /hac_node)
      ros__parameters: {window_s: 20.0}
    /robot1/hac_node:          # ... in a namespace (or nested: robot1: {hac_node: {...}})
      ros__parameters: {...}
    slam_node:                 # another node's section: not ours, left alone
      ros__parameters: {...}

As rcl does: a key is a node's fully qualified name (the leading ``/`` optional), nested keys are
namespaces, ``*`` matches one name and ``**`` any number; every section that matches the node
applies, in file order (a later value wins); nested parameters are dotted names
(``qos_overrides./hac/pose.publisher.depth``). ROS's own parameters (``use_sim_time``,
``qos_overrides.*``) are accepted and are not hac_ros'.

What is wrong is said with the closest right name: a misspelt parameter (``window_sec``: did you
mean ``window_s``?), a section whose node name is a few edits from the node's (``hac_nod:``, whose
parameters would otherwise be ignored in silence), a file with no section for the node at all.
The replay's own file is strict (:func:`load_params` raises :class:`ParameterError` for a misspelt
parameter; the other two are logged warnings); the node only warns, as ROS ignores what it does
not declare (:mod:`hac_ros.ros.parameters`).
"""
from __future__ import annotations

import difflib
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.params import NODE_NAME, HacParams, names

PARAMETERS_KEY = 'ros__parameters'
# Parameters every ROS 2 node has (or that ROS reads for it): accepted, not hac_ros'
ROS_OWN_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})
ROS_OWN_PREFIXES = ('qos_overrides.',)
NEAR_MISS_EDITS = 2  # a section key this many edits from the node's name is probably meant for it
# PyYAML's safe loader, on libyaml when it has it (as rcl's parser: fast, and a nesting limit
# where the pure-Python parser takes seconds over a deep file)
LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)

log = logging.getLogger(__name__)


@dataclass
class ParamsFile:
    """One parameters file as it applies to one node.

    node: the node's fully qualified name it was read for (``/hac_node``); sections: the keys that
    apply to it, in file order; values: its parameters that are hac_ros' (:class:`HacParams`
    fields); ros_own: those that are ROS's (``use_sim_time``, ``qos_overrides.*``); unknown:
    the rest (misspelt?); near_misses: section keys a few edits from the node's name.
    """

    path: Path
    node: str
    sections: list[str] = field(default_factory=list)
    values: dict[str, Any] = field(default_factory=dict)
    ros_own: dict[str, Any] = field(default_factory=dict)
    unknown: list[str] = field(default_factory=list)
    near_misses: list[str] = field(default_factory=list)

    def section_problems(self) -> list[str]:
        """The sections that look meant for the node but are not its, and a file that has none
        for it: each one line."""
        problems = [f'{self.path}: section {key!r} is not {self.node}\'s: a misspelt node name? '
                    'its parameters are not used' for key in self.near_misses]
        if not self.sections:
            problems.append(f'{self.path} has no section for {self.node} (a "{_name(self.node)}:'
                            f' {{{PARAMETERS_KEY}: ...}}" or "/**:" one): the defaults are used')
        return problems

    def params(self) -> HacParams:
        """The parameters (the defaults where the file says nothing); strict: a misspelt name is
        a :class:`ParameterError` naming the closest valid one."""
        if self.unknown:
            raise ParameterError(f'{self.path}: {unknown_names(self.unknown)}')
        return HacParams.from_dict(self.values)


def read_params_file(path: str | Path, node_name: str = NODE_NAME,
                     namespace: str | None = None) -> ParamsFile:
    """The file at ``path`` as it applies to the node ``node_name`` in ``namespace``.

    namespace None (the replay, which has none): the namespace of the file's sections for
    ``node_name`` when they all name the same one (``/robot1/hac_node:``), else the root; sections
    for it in several namespaces are a :class:`ParameterError`. Raises ParameterError for a file
    that cannot be read or is not a parameters file.
    """
    path = Path(path)
    sections = list(_sections(path, _top(path, _load_yaml(path))))
    if namespace is None:
        namespace = _namespace_of(path, [key for key, _ in sections], node_name)
    node = _join(namespace, node_name)
    read = ParamsFile(path, node)
    for key, parameters in sections:
        if _matches(_tokens(key), _tokens(node)):
            read.sections.append(key)
            for name, value in _flatten(path, key, parameters):
                read.values[name] = value
        elif _near_miss(_name(key), _name(node)):
            read.near_misses.append(key)
    for name in list(read.values):
        if name in ROS_OWN_PARAMETERS or name.startswith(ROS_OWN_PREFIXES):
            read.ros_own[name] = read.values.pop(name)
        elif name not in names():
            read.unknown.append(name)
            del read.values[name]
    return read


def load_params(params_file: str | Path | None, overrides: Mapping[str, Any] | None = None
                ) -> HacParams:
    """The parameters of a command: ``params_file`` read strictly for ``hac_node`` (the defaults
    when None; :meth:`ParamsFile.section_problems` logged as warnings), then ``overrides`` (a
    command line's options; None values are options not given)."""
    params = HacParams()
    if params_file:
        read = read_params_file(params_file)
        for problem in read.section_problems():
            log.warning('%s', problem)
        params = read.params()
    changes = {k: v for k, v in (overrides or {}).items() if v is not None}
    return params.replace(**changes) if changes else params


def unknown_names(unknown: list[str]) -> str:
    """``unknown parameter 'window_sec' (did you mean 'window_s'?), ...``: one line."""
    said = []
    for name in unknown:
        close = difflib.get_close_matches(name, names(), n=1)
        said.append(f'{name!r}' + (f' (did you mean {close[0]!r}?)' if close else ''))
    return f'unknown parameter{"s" if len(unknown) > 1 else ""} {", ".join(said)}'


# ---------------------------------------------------------------------------------------- the file
def check_params_file(path: str | Path) -> None:
    """What rcl would refuse in the parameters file at ``path``, as a :class:`ParameterError` of
    one line naming the file, the line and what is wrong (``hac_node`` calls it before
    ``rclpy.init``, where rcl parses the file and would end the process with its own
    traceback): a file that cannot be read, is not UTF-8 or not YAML, uses YAML aliases, or has a
    section that is not a node's ``ros__parameters``. An empty file passes, as in rcl."""
    path = Path(path)
    data = _load_yaml(path)
    if data is not None:
        for key, parameters in _sections(path, _top(path, data)):
            for _ in _flatten(path, key, parameters):
                pass


def _load_yaml(path: Path) -> Any:
    """The YAML document of the file at ``path`` (None when it is empty). ParameterError, one line
    naming the file (and the line and column where the YAML says), for anything else: a file that
    cannot be read (a directory, no permission), bytes that are not UTF-8, invalid YAML, YAML
    aliases (ROS 2's parser refuses them: no alias cycle gets further), nesting too deep, a value
    YAML cannot build (an integer of thousands of digits)."""
    where = f'parameters file {printable(path)}'
    if path.is_dir():
        raise ParameterError(f'{where} is a directory, not a file')
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ParameterError(f'cannot read {where}: {exc.strerror or exc}') from exc
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        line, column = _line_and_column(raw, exc.start)
        raise ParameterError(f'{where}, line {line}, column {column}: not UTF-8 text (byte '
                             f'0x{raw[exc.start]:02x}): is it a parameters file?') from exc
    try:
        alias = next((event for event in yaml.parse(text, Loader=LOADER)
                      if isinstance(event, yaml.AliasEvent)), None)
        data = None if alias is not None else yaml.load(text, Loader=LOADER)
    except yaml.MarkedYAMLError as exc:
        raise ParameterError(f'{where}, {_yaml_problem(exc)}') from exc
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow (NUL, ...)
        line, column = _line_and_column(raw, len(text[:exc.position].encode('utf-8')))
        char = chr(exc.character) if isinstance(exc.character, int) else str(exc.character)
        raise ParameterError(f'{where}, line {line}, column {column}: not valid YAML: the '
                             f'character {printable(repr(char))} is not allowed') from exc
    except yaml.YAMLError as exc:
        raise ParameterError(f'{where}: not valid YAML: {_one_line(str(exc))}') from exc
    except RecursionError as exc:
        raise ParameterError(f'{where}: nested too deeply to be a parameters file') from exc
    except ValueError as exc:  # a value YAML's constructors refuse
        raise ParameterError(f'{where}: a value YAML cannot read: {_one_line(str(exc))}') from exc
    if alias is not None:
        mark = alias.start_mark
        raise ParameterError(f'{where}, line {mark.line + 1}, column {mark.column + 1}: the '
                             f'alias *{printable(alias.anchor)}: ROS 2 parameters files cannot '
                             'use YAML aliases (rcl refuses them)')
    return data


def _top(path: Path, data: Any) -> dict[Any, Any]:
    """The document's top level: a mapping of node names (ParameterError otherwise)."""
    if not isinstance(data, dict):
        raise ParameterError(f'parameters file {printable(path)}: expected node names at the top '
                             f'("{NODE_NAME}: {{{PARAMETERS_KEY}: ...}}")')
    return data


def _line_and_column(raw: bytes, offset: int) -> tuple[int, int]:
    """Line and column (1-based, in characters of the valid text before it) of byte ``offset``."""
    before = raw[:offset]
    line_start = before.rfind(b'\n') + 1
    return before.count(b'\n') + 1, len(before[line_start:].decode('utf-8', 'replace')) + 1


def _yaml_problem(exc: yaml.MarkedYAMLError) -> str:
    """``line 3, column 15: not valid YAML: expected ',' or ']' (while parsing a flow sequence
    at line 3, column 13)``: where (the problem's mark, else the context's) and what."""
    mark = exc.problem_mark or exc.context_mark
    at = f'line {mark.line + 1}, column {mark.column + 1}: ' if mark is not None else ''
    what = _one_line(exc.problem or 'invalid YAML')
    context = ''
    if exc.context:
        context = f' ({_one_line(exc.context)}'
        place = exc.context_mark
        if place is not None and (mark is None or (place.line, place.column) != (mark.line,
                                                                                  mark.column)):
            context += f' at line {place.line + 1}, column {place.column + 1}'
        context += ')'
    return f'{at}not valid YAML: {what}{context}'


def _one_line(text: str) -> str:
    return printable(' '.join(text.split()))


def _sections(path: Path, data: Mapping[Any, Any], prefix: str = ''
              ) -> Iterator[tuple[str, dict[Any, Any]]]:
    """(node name or pattern as the file writes it, its ros__parameters) in file order; a key
    without ros__parameters is a namespace around more keys (``robot1: {hac_node: ...}`` is
    ``robot1/hac_node``)."""
    for key, value in data.items():
        name = f'{prefix}/{key}' if prefix else str(key)
        if not isinstance(value, dict):
            raise ParameterError(f'parameters file {path}: {name} holds {value!r}, not '
                                 f'"{PARAMETERS_KEY}:" or namespaced node names (a ROS 2 '
                                 f'parameters file is "{NODE_NAME}: {{{PARAMETERS_KEY}: ...}}")')
        if PARAMETERS_KEY in value:
            parameters = value[PARAMETERS_KEY]
            if not isinstance(parameters, dict) or len(value) > 1:
                raise ParameterError(f'parameters file {path}: {name}: expected only '
                                     f'"{PARAMETERS_KEY}:" and a mapping under it')
            yield name, parameters
        else:
            yield from _sections(path, value, name)


def _flatten(path: Path, key: str, parameters: Mapping[Any, Any], prefix: str = ''
             ) -> Iterator[tuple[str, Any]]:
    """Nested parameters as ROS names them: ``a: {b: 1}`` is ``a.b``."""
    for name, value in parameters.items():
        dotted = f'{prefix}{name}'
        if isinstance(value, dict):
            yield from _flatten(path, key, value, dotted + '.')
        else:
            yield dotted, value


# ---------------------------------------------------------------------------------------- names
def _tokens(name: str) -> list[str]:
    return [token for token in name.split('/') if token]


def _join(namespace: str, name: str) -> str:
    """``/ns/name`` from a namespace and a name, either with or without slashes."""
    return '/' + '/'.join(_tokens(namespace) + _tokens(name))


def _name(key: str) -> str:
    """The node name of a section key (its last token)."""
    tokens = _tokens(key)
    return tokens[-1] if tokens else ''


def _matches(pattern: list[str], name: list[str]) -> bool:
    """rcl's wildcards: ``*`` one token, ``**`` any number of tokens (none included)."""
    if not pattern:
        return not name
    head, rest = pattern[0], pattern[1:]
    if head == '**':
        return any(_matches(rest, name[i:]) for i in range(len(name) + 1))
    return bool(name) and head in ('*', name[0]) and _matches(rest, name[1:])


def _namespace_of(path: Path, keys: list[str], node_name: str) -> str:
    """The one namespace the file's sections give ``node_name`` (wildcards aside), else ``/``."""
    namespaces = sorted({_join('/'.join(_tokens(key)[:-1]), '') for key in keys
                         if _name(key) == node_name and '*' not in key})
    if len(namespaces) > 1:
        raise ParameterError(f'parameters file {path} has {node_name} sections for the '
                             f'namespaces {", ".join(namespaces)}: give a file with one')
    return namespaces[0] if namespaces else '/'


def _near_miss(key: str, node_name: str) -> bool:
    return '*' not in key and key != node_name and \
        _edit_distance(key, node_name) <= NEAR_MISS_EDITS


def _edit_distance(a: str, b: str) -> int:
    """Levenshtein distance: insertions, deletions and substitutions."""
    previous = list(range(len(b) + 1))
    for i, char_a in enumerate(a, 1):
        current = [i]
        for j, char_b in enumerate(b, 1):
            current.append(min(previous[j] + 1, current[j - 1] + 1,
                               previous[j - 1] + (char_a != char_b)))
        previous = current
    return previous[-1]
