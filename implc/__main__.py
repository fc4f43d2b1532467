"""``python -m implc``: the command line (:mod:`implc.cli`), with Ctrl-C during start-up a clean exit."""

import sys

try:
    from .cli import main
except KeyboardInterrupt:
    sys.stderr.write("implc: interrupted\n")
    sys.exit(130)

sys.exit(main())
