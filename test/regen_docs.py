"""The docs' generated blocks: text between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``
markers, made from the code that is their one source. ``make docs`` rewrites them;
``test/test_docs.py`` fails while one is out of date.

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
    from hac_ros.core.reasons import markdown_table

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


# (page, block name) -> what the block holds
BLOCKS: dict[tuple[str, str], Callable[[], str]] = {
    ('docs/node.md', 'reasons'): _reasons,
    ('docs/inputs.md', 'layouts'): _layouts,
    ('docs/people.md', 'people_params'): _people_params,
    ('docs/people.md', 'people_reasons'): _people_reasons,
}


def _pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf'(<!-- {name}:begin -->\n)(.*?)(<!-- {name}:end -->)', re.S)


def stale(write: bool = False) -> list[str]:
    """The blocks whose text is not what the code makes (rewritten with ``write``); a page
    missing a block's markers is listed too."""
    out = []
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
