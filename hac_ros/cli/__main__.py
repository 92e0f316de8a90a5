"""``python -m hac_ros.cli``: the ``hac`` command."""
import sys

from hac_ros.cli import main

sys.exit(main())
