"""``python -m app``: the ``sbsc`` command line with the app's commands, installed or not."""

import sys

from sbsc_core.cli import main, plugin_registrars

from .cli import REGISTRARS

sys.exit(main(registrars=[*REGISTRARS, *(r for r in plugin_registrars() if r not in REGISTRARS)]))
