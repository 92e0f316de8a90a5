"""Strings from outside are escaped before a terminal or a log sees them (hac_ros.core.basics.printable)."""
from __future__ import annotations

import logging

from hac_ros.cli.terminal import CommandFormatter
from hac_ros.core.basics.printable import printable, printable_lines

# what a hostile recording or file name can hold: ESC (a control sequence that clears the screen),
# BEL, CR, a newline, DEL, a C1 control, a right-to-left override, a lone surrogate (a file name
# that is not UTF-8, as os.fsdecode gives it)
HOSTILE = 'cam\x1b[2J\x07\rx\ny\x7f\x9b\u202etxt\udcff'


def test_every_character_a_terminal_would_obey_is_escaped_as_a_repr_writes_it():
    shown = printable(HOSTILE)
    assert shown == 'cam\\x1b[2J\\x07\\rx\\ny\\x7f\\x9b\\u202etxt\\udcff'
    assert shown.isprintable()
    shown.encode('utf-8')  # a lone surrogate would not encode


def test_printable_text_and_every_script_are_left_as_they_are():
    for text in ('/slam/pose', 'map_1', 'Kamera Überblick', 'カメラ', 'a b\\c', ''):
        assert printable(text) == text


def test_lines_keep_their_breaks_and_nothing_else():
    assert printable_lines('summary\n  topic /a\x1b[31m\n') == 'summary\n  topic /a\\x1b[31m\n'



def test_a_log_line_of_the_command_is_written_escaped_and_the_record_left_unchanged():
    """The command's formatter is the last net (names are escaped where they are put in a
    message): every control character but the record's own line breaks."""
    name = HOSTILE.replace('\n', '')
    record = logging.LogRecord('hac_ros.test', logging.WARNING, __file__, 1,
                               'topic %s is missing\n  (twice)', (name,), None)
    text = CommandFormatter('replay').format(record)
    assert text == f'hac replay: warning: topic {printable(name)} is missing\n  (twice)'
    assert record.getMessage() == f'topic {name} is missing\n  (twice)'  # as other handlers see it
