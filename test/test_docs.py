"""The docs say what the code does: the command lines they show use options the commands have, the
parameters they set are valid, the defaults they state are the code's, and the launch file passes
the node parameters it has, at their defaults. (The parameter table of docs/node.md and
config/hac.yaml are held to the code by test_node.py.)"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
import yaml

from hac_ros.core.rules.params import HacParams, describe, names

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / 'README.md', *sorted((REPO / 'docs').glob('*.md'))]
# other software's parameters of the same name, with their own defaults
OTHERS = {('inputs.md', 'camera_frame')}  # stella_vslam_ros' camera_frame (default camera_frame)


def _text(path: Path) -> str:
    return path.read_text(encoding='utf-8')


def _snippets(text: str) -> list[str]:
    """What a reader would type: each line of a fenced code block (continuation lines joined)
    and each inline code span."""
    lines = [line for block in re.findall(r'```[a-z]*\n(.*?)```', text, re.S)
             for line in block.replace('\\\n', ' ').splitlines()]
    return lines + re.findall(r'`([^`\n]+)`', text)


def _subcommand_options() -> dict[str, set[str]]:
    from hac_ros.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == 'command')
    return {name: {o for a in p._actions for o in a.option_strings}
            for name, p in sub.choices.items()}


def test_every_hac_command_line_in_the_docs_uses_options_the_command_has():
    options = _subcommand_options()
    used, wrong = 0, []
    for page in PAGES:
        for snippet in _snippets(_text(page)):
            for m in re.finditer(r'\bhac (\w+)((?:\s+[^\s#|`]+)*)', snippet):
                command, rest = m.groups()
                if command not in options:
                    if command != 'COMMAND':
                        wrong.append(f'{page.name}: no command hac {command}: {snippet}')
                    continue
                for flag in re.findall(r'(?<![\w-])(--?[a-zA-Z][\w-]*)', rest):
                    used += 1
                    if flag not in options[command]:
                        wrong.append(f'{page.name}: hac {command} has no {flag}: {snippet}')
    assert used > 100  # the docs' command lines were found
    assert wrong == []


def _parameter_sets(text: str) -> list[dict]:
    """The parameters the docs set: parameters files written with printf or shown as YAML
    (their hac_node section), and ``-p name:=value`` on one command line."""
    found = []
    for body in re.findall(r"printf '([^']*)'", text):
        found.append(yaml.safe_load(body.replace('\\n', '\n')))
    for block in re.findall(r'```ya?ml\n(.*?)```', text, re.S):
        found.append(yaml.safe_load(block))
    sets = [f['hac_node']['ros__parameters'] for f in found if f and 'hac_node' in f]
    for snippet in _snippets(text):
        pairs = re.findall(r'-p (\w+):=(\S+)', snippet)
        if pairs and 'hac_people_node' not in snippet:
            sets.append({k: yaml.safe_load(v) for k, v in pairs})
    return sets


def test_every_parameter_set_the_docs_show_is_valid():
    sets = [(page.name, s) for page in PAGES for s in _parameter_sets(_text(page))]
    assert len(sets) >= 4
    for _, values in sets:
        HacParams.from_dict(values)  # raises naming the parameter: unknown or invalid


def test_the_people_node_parameters_the_docs_show_are_its_own():
    """hac_people_node's command lines set its parameters (hac_ros.people.params), and
    docs/people.md's table is the code's (a block of regen_docs)."""
    from regen_docs import BLOCKS

    from hac_ros.people.params import PeopleParams, parameter_table

    shown = [dict(re.findall(r'-p (\w+):=(\S+)', snippet)) for page in PAGES
             for snippet in _snippets(_text(page)) if 'hac_people_node' in snippet]
    shown = [s for s in shown if s]
    assert shown
    for values in shown:
        PeopleParams.from_dict({k: yaml.safe_load(v) for k, v in values.items()})
    assert BLOCKS[('docs/people.md', 'people_params')]() == parameter_table() + '\n'



def _stated_defaults(text: str) -> list[tuple[str, object, object]]:
    """(name, the value stated, the code's default) for each "`name` (`value`)" or "`name`
    (default value)" where name is a parameter and value is one of its type: a string, or a
    number with an optional unit s, m or % (in parentheses after a number parameter, a word in
    backticks is something else: the reason it is counted under, say)."""
    stated = []
    pattern = re.compile(r'`(\w+)` \((?:default,? )?(`[^`]+`|[-+\d.e]+(?: ?(?:s|m|%))?)[),;]')
    for name, value in pattern.findall(text):
        if name not in names():
            continue
        default = describe(name)['default']
        value = value.strip('`')
        if isinstance(default, str):
            stated.append((name, value, default))
            continue
        number = re.fullmatch(r'([-+\d.e]+) ?(s|m|%)?', value)
        if number and isinstance(default, (int, float)):
            scale = 0.01 if number.group(2) == '%' else 1.0
            stated.append((name, float(number.group(1)) * scale, default))
    return stated


def test_the_defaults_the_docs_state_are_the_codes():
    stated = [(page.name, *each) for page in PAGES for each in _stated_defaults(_text(page))
              if (page.name, each[0]) not in OTHERS]
    assert len(stated) >= 15
    wrong = [f'{page}: {name} ({value}), the code\'s default {default!r}'
             for page, name, value, default in stated if value != pytest.approx(default)]
    assert wrong == []


def test_the_launch_file_passes_node_parameters_at_their_defaults():
    """launch/hac.launch.py is read, not imported (launch is not installable here): each launch
    argument named after a parameter defaults to the parameter's default, and the node gets only
    parameters it has."""
    tree = ast.parse(_text(REPO / 'launch' / 'hac.launch.py'))
    declared = {}
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and getattr(call.func, 'id', '') == 'DeclareLaunchArgument':
            name = ast.literal_eval(call.args[0])
            default = next(k.value for k in call.keywords if k.arg == 'default_value')
            declared[name] = ast.literal_eval(default) if isinstance(default, ast.Constant) else None
    passed = [ast.literal_eval(key) for d in ast.walk(tree) if isinstance(d, ast.Dict)
              for key in d.keys if isinstance(key, ast.Constant) and isinstance(key.value, str)]
    assert passed and set(passed) <= set(names()), passed
    for name in passed:
        assert declared[name] == describe(name)['default'], name


def test_the_input_topics_interface_md_lists_are_parameters_with_those_defaults():
    """docs/interface.md's input table: "`name` (`default`)" rows name parameters."""
    listed = re.findall(r'^\| `(\w+)` \(`([^`]*)`', _text(REPO / 'docs' / 'interface.md'), re.M)
    assert len(listed) >= 4
    assert [(name, describe(name)['default']) for name, _ in listed] == listed


def _headings(page: Path) -> list[str]:
    return [h.strip() for h in re.findall(r'^#+ (.+)$', _text(page), re.M)]


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r'[^\w\- ]', '', heading.lower()).replace(' ', '-')


def _code_files() -> list[Path]:
    """The product's code and configuration, whose comments and docstrings cite docs/ too."""
    return [p for folder in ('hac_ros', 'msg_adapters', 'launch', 'config')
            for p in sorted((REPO / folder).rglob('*')) if p.suffix in ('.py', '.yaml', '.xml')]


def test_links_and_named_sections_point_to_headings_that_exist():
    """[text](page.md#anchor) links and the 'docs/page.md, "Section"' references of the docs, the
    code and the configuration."""
    pages = {page.name: page for page in PAGES}
    checked, broken = 0, []
    for page in PAGES + _code_files():
        text = _text(page).replace('#', ' ')  # a reference wrapped across comment lines
        for target, anchor in re.findall(r'\]\(([\w./-]*\.md|)#([\w-]+)\)', _text(page)):
            linked = (page.parent / target).resolve() if target else page
            checked += 1
            if anchor not in {_anchor(h) for h in _headings(linked)}:
                broken.append(f'{page.name}: {target}#{anchor}')
        for name, section in re.findall(r'(?:docs/)?([\w-]+\.md),?\s+\(?"([^"]+)"', text):
            section = ' '.join(section.split()).replace('`', '')  # wrapped across lines
            checked += 1
            if name not in pages or not any(h.replace('`', '').startswith(section)
                                            for h in _headings(pages[name])):
                broken.append(f'{page.name}: {name}, "{section}"')
    assert checked > 30
    assert broken == []


def test_the_readme_layout_names_every_library_module():
    """README's "Layout" names each module of the library's subpackages (the simulator's and the
    command's are described by what they do)."""
    block = re.search(r'## Layout\n.*?```\n(.*?)```', _text(REPO / 'README.md'), re.S)
    assert block
    described: dict[str, str] = {}
    current = ''
    for line in block.group(1).splitlines():
        head = re.match(r'(hac_ros/\w+)/', line)
        current = head.group(1) if head else current if line.startswith(' ') else ''
        if current:
            described[current] = described.get(current, '') + ' ' + line
    packages = ('core', 'ros', 'bridge', 'recording', 'replay', 'batch', 'files', 'evaluation',
                'people')
    def modules(package: str) -> list[Path]:  # the core's rooms too, not the layouts' modules
        folder = REPO / 'hac_ros' / package
        found = folder.rglob('*.py') if package == 'core' else folder.glob('*.py')
        return sorted(m for m in found if m.stem != '__init__' and 'layouts' not in m.parts)

    missing = [str(module.relative_to(REPO)) for package in packages
               for module in modules(package)
               if not re.search(rf'\b{module.stem}\b', described.get(f'hac_ros/{package}', ''))]
    assert missing == []


# ---------------------------------------------------------------- layouts: one source, the registry
def _layout_statements(text: str) -> list[str]:
    """What a text says about the built-in layouts that the registry (hac_ros.core.layouts) does
    not: a list of choices (names ending with ``custom``) that leaves a built-in layout out, a
    name that is not a layout in such a list, and a joint count stated for a layout ("smpl24: 24",
    "`coco17` and `h36m17`: 17", "24 for `smpl24`", "`smpl24`, K = 24") that is not its K."""
    from hac_ros.core.layouts import BUILT_IN

    name = r'`?([a-z][a-z0-9]*\d\d|custom)`?(?: \([^)]*\))?'
    separator = r'(?:,? (?:or|and) |, | \| | / )'
    wrong = []
    for m in re.finditer(rf'{name}(?:{separator}{name})+', text):
        listed = re.findall(name, m.group(0))
        if listed[-1] != 'custom':
            continue
        missing = [n for n in BUILT_IN if n not in listed]
        unknown = [n for n in listed if n not in BUILT_IN and n != 'custom']
        if missing or unknown:
            wrong.append(f'"{m.group(0)}" lists {listed}: missing {missing}, unknown {unknown}')
    known = '|'.join(BUILT_IN)
    counts = [(m.group(1), m.group(2)) for m in re.finditer(
        rf'`?({known})`?(?:,? K =|:) (\d+)\b', text)]
    counts += [(m.group(2), m.group(1)) for m in re.finditer(rf'\b(\d+) for `?({known})\b', text)]
    for m in re.finditer(rf'`?({known})`? and `?({known})`?: (\d+)\b', text):
        counts += [(m.group(1), m.group(3)), (m.group(2), m.group(3))]
    wrong += [f'{layout}: {count} joints stated, K is {BUILT_IN[layout].joints_per_person}'
              for layout, count in sorted(set(counts)) if int(count) != BUILT_IN[layout].joints_per_person]
    return wrong


def test_the_layout_checker_finds_stale_lists_and_counts():
    """The check below can fail: a list of choices without a layout, a layout that is not one,
    a wrong count, each form."""
    from hac_ros.core.layouts import BUILT_IN

    all_but_one = [*BUILT_IN][:-1]
    assert len(_layout_statements('(' + ' | '.join([*all_but_one, 'custom']) + ')')) == 1
    assert _layout_statements('(' + ' | '.join([*BUILT_IN, 'custom']) + ')') == []
    assert len(_layout_statements('`smpl24`, `coco18`, `custom`')) == 1
    assert len(_layout_statements('set joint_layout (smpl24: 24, coco17: 24)')) == 1
    assert len(_layout_statements('24 for `coco17`, 17 for `h36m17`')) == 1
    assert len(_layout_statements('`coco17` and `h36m17`: 33')) == 2
    assert len(_layout_statements('`h36m17`, K = 24')) == 1
    assert _layout_statements('`coco17` / `smpl24` for a 17-joint or a 24-joint model') == []


def test_the_docs_and_code_name_the_layouts_and_counts_the_registry_has():
    """README, docs/, config/ and the package's own texts: every list of joint_layout's choices
    has every built-in layout, every stated joint count is the layout's; docs/inputs.md's table of
    layouts is the registry's (hac_ros.core.layouts.markdown_table, a block of regen_docs)."""
    from regen_docs import BLOCKS

    wrong = [f'{page.relative_to(REPO)}: {w}' for page in PAGES + _code_files()
             for w in _layout_statements(_text(page))]
    assert wrong == []
    assert 'layouts' in {name for _, name in BLOCKS}  # the table: a generated block (make docs)


def test_config_comments_list_each_parameters_choices():
    """config/hac.yaml: the "(a | b | c)" a parameter's comment ends with is its choices."""
    listed = re.findall(r'^    (\w+): .*\(([\w | ]+)\)$', _text(REPO / 'config' / 'hac.yaml'),
                        re.M)
    with_choices = [(n, c) for n, c in listed if ' | ' in c]
    assert len(with_choices) >= 8
    assert [(n, c.split(' | ')) for n, c in with_choices] == [
        (n, list(describe(n)['choices'])) for n, _ in with_choices]


def test_the_generated_blocks_of_the_docs_are_up_to_date():
    """The reason table, the layouts, the people node's tables, the output topics (README,
    docs/interface.md, docs/node.md's QoS) are made from their one source: `make docs` rewrites
    them."""
    from regen_docs import stale

    assert stale() == [], 'run `make docs` (test/regen_docs.py)'


def test_every_output_topic_the_docs_and_files_name_is_in_the_table():
    """A renamed or removed output topic shows wherever it is still named by hand: README, the
    docs, the RViz config and robot_localization's example (hac_ros.bridge.topics)."""
    from hac_ros.bridge.topics import TOPICS

    known = {t.name for t in TOPICS}
    pages = [REPO / 'README.md', *sorted((REPO / 'docs').glob('*.md')),
             REPO / 'rviz' / 'hac.rviz', REPO / 'config' / 'robot_localization.yaml']
    named = {(page.name, name) for page in pages
             for name in re.findall(r'(?<![\w/.~])/?(hac/[a-z_]+)\b', page.read_text())}
    assert len(named) > 20
    assert {(page, name) for page, name in named if name not in known} == set()


# the calls that count, announce or find a reason, with the reason as a string literal
_REASON_CALLS = re.compile(
    r"""(?:_reject|\.reject|_rejected_sample\([^)]*?|no_sample|Finding|reason_text|events\[|"""
    r"""conditions\(\)\[)\(?\s*'([a-z_]+)'""")


def test_every_reason_the_code_gives_is_in_the_one_table():
    """A reason counted, held or found anywhere in the library is an entry of the core's table
    (so its text, level and remedy are said once); the transport reasons are made per input kind."""
    from hac_ros.core.rules.reasons import REASONS

    used: set[str] = set()
    for path in (REPO / 'hac_ros').rglob('*.py'):
        if path not in people_node_files():  # its own table, below
            used.update(_REASON_CALLS.findall(_text(path)))
    used.update(f'{kind}_{what}' for kind in ('pose', 'joints', 'camera_info', 'cloud')
                for what in ('lost', 'wrong_type'))
    assert len(used) > 30
    assert sorted(used - set(REASONS)) == []


def test_every_reason_that_can_warn_says_what_to_do():
    """Each reason that can make a status WARN has a remedy in the one table, or says there is
    none ("none: ..."): the node appends it to the warning it logs, docs/node.md lists it."""
    from hac_ros.core.rules.reasons import REASONS

    warning = {key: r for key, r in REASONS.items() if r.makes_warn}
    assert len(warning) > 10
    assert sorted(key for key, r in warning.items() if len(r.remedy.strip()) < 4) == []
    table = (REPO / 'docs' / 'node.md').read_text(encoding='utf-8')
    assert all(r.remedy in table for r in warning.values())


def people_node_files() -> set[Path]:
    """The people front end and its node: their reasons are hac_ros/people/reasons.py's."""
    return {*(REPO / 'hac_ros' / 'people').rglob('*.py'),
            REPO / 'hac_ros' / 'ros' / 'people_node.py'}


def test_every_reason_the_people_node_gives_is_in_its_table():
    """hac_people_node's reasons (hac_ros/people/ and the node, hac_ros/ros/people_node.py): its
    own one table."""
    from hac_ros.people.reasons import REJECTIONS

    used: set[str] = set()
    for path in people_node_files():
        used.update(_REASON_CALLS.findall(_text(path)))
    assert len(used) >= 5
    assert sorted(used - set(REJECTIONS)) == []
