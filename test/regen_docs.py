"""The docs' generated blocks: text between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``
markers, made from the code that is their one source, and the files made whole (config/hac.yaml).
``make docs`` rewrites them; ``test/test_docs.py`` fails while one is out of date.

    python test/regen_docs.py          # rewrite the blocks that changed
"""
from __future__ import annotations

import re
import sys
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def _reasons() -> str:
    from hac_ros.core.rules.reasons import markdown_table

    return markdown_table()


def _layouts() -> str:
    from hac_ros.core.layouts import markdown_table

    return markdown_table() + '\n'


def _people_params() -> str:
    from hac_ros.people.params import parameter_table

    return parameter_table() + '\n'


def _people_reasons() -> str:
    from hac_ros.people.reasons import markdown_table

    return markdown_table()


def _outputs_table() -> str:
    from hac_ros.bridge.topics import markdown_table

    return markdown_table()


def _qos() -> str:
    from hac_ros.ros.qos import qos_table

    return qos_table()


def _readme_outputs() -> str:
    from hac_ros.bridge.topics import readme_outputs

    return readme_outputs()


def _parameters() -> str:
    from hac_ros.ros.parameters import parameter_table

    return parameter_table() + '\n'


CONFIG_HEAD = """\
# hac_node parameters, every one at its default (docs/node.md; the file format: docs/interface.md).
# One file serves the node and the replay:
#   ros2 run hac_ros hac_node --ros-args --params-file config/hac.yaml
#   hac replay --params config/hac.yaml ...
# Installed to share/hac_ros/config/hac.yaml. Ranges and choices are enforced when set,
# also at runtime (ros2 param set); docs/node.md says what a runtime change does.
# Made by `make docs` from hac_ros/core/rules/params.py (test/test_docs.py holds it to it).
hac_node:
  ros__parameters:
"""


def _config() -> str:
    from hac_ros.ros.parameters import config_parameters

    return CONFIG_HEAD + config_parameters()


# (page, block name) -> what the block holds
BLOCKS: dict[tuple[str, str], Callable[[], str]] = {
    ('docs/node.md', 'reasons'): _reasons,
    ('docs/inputs.md', 'layouts'): _layouts,
    ('docs/people.md', 'people_params'): _people_params,
    ('docs/people.md', 'people_reasons'): _people_reasons,
    ('docs/interface.md', 'outputs'): _outputs_table,
    ('docs/node.md', 'qos'): _qos,
    ('README.md', 'outputs'): _readme_outputs,
    ('docs/node.md', 'params'): _parameters,
}
# file -> its whole text
FILES: dict[str, Callable[[], str]] = {'config/hac.yaml': _config}


def _pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf'(<!-- {name}:begin -->\n)(.*?)(<!-- {name}:end -->)', re.S)


def stale(write: bool = False) -> list[str]:
    """The blocks and files whose text is not what the code makes (rewritten with ``write``);
    a page missing a block's markers is listed too."""
    out = []
    for page, make in FILES.items():
        path, wanted = REPO / page, make()
        if path.read_text(encoding='utf-8') != wanted:
            out.append(page)
            if write:
                path.write_text(wanted, encoding='utf-8')
    for (page, name), make in BLOCKS.items():
        path = REPO / page
        text = path.read_text(encoding='utf-8')
        match = _pattern(name).search(text)
        if match is None:
            out.append(f'{page}: no <!-- {name}:begin/end --> markers')
            continue
        wanted = make()
        if match.group(2) != wanted:
            out.append(f'{page}: block {name}')
            if write:
                text = text[:match.start(2)] + wanted + text[match.end(2):]
                path.write_text(text, encoding='utf-8')
    return out


if __name__ == '__main__':
    for line in stale(write=True):
        print('rewrote', line)
