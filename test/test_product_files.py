"""The product stands on its own: its interface is in docs/, and nothing a user's clone ships
refers to the team's design notes beside the repository (tests and benchmarks may read the data
there)."""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# What a user's clone ships: the packages, their docs, configuration, launch and packaging files
PRODUCT = ('hac_ros', 'msg_adapters', 'docs', 'config', 'launch', 'rviz', 'resource',
           'README.md', 'bags/README.md', 'package.xml', 'setup.py', 'setup.cfg', 'Makefile',
           'ruff.toml')
TEXT_SUFFIXES = {'.py', '.md', '.yaml', '.yml', '.xml', '.rviz', '.cfg', '.toml', '.txt', ''}
# The design notes beside the repository, however they are named
OUTSIDE = re.compile(r'\.\./shared|shared/SPEC|\bSPEC\b')
DOC_LINK = re.compile(r'\bdocs/([\w-]+\.md)')


def product_files() -> list[Path]:
    files: list[Path] = []
    for name in PRODUCT:
        path = REPO / name
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            files += [p for p in sorted(path.rglob('*')) if p.is_file()
                      and p.suffix in TEXT_SUFFIXES and '__pycache__' not in p.parts]
    return files


def test_the_product_does_not_refer_to_the_notes_beside_the_repository():
    assert len(product_files()) > 100  # the packages and the docs are there
    found = [f'{path.relative_to(REPO)}:{number}: {line.strip()}'
             for path in product_files()
             for number, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1)
             if OUTSIDE.search(line)]
    assert found == [], 'point to docs/interface.md instead:\n' + '\n'.join(found)


def test_every_docs_page_the_product_names_exists():
    pages = {p.name for p in (REPO / 'docs').glob('*.md')}
    assert 'interface.md' in pages
    missing = [f'{path.relative_to(REPO)}: docs/{page}' for path in product_files()
               for page in DOC_LINK.findall(path.read_text(encoding='utf-8')) if page not in pages]
    assert missing == []
