"""``python -m implc``: the command line (:mod:`implc.cli.commands`), with Ctrl-C during start-up a clean exit."""

import sys

try:
    from .cli.commands import main

    status = main(restore_handlers=False)  # the process ends here: a late signal is only noted
except KeyboardInterrupt:  # before main() had its handlers in place
    sys.stderr.write("implc: interrupted\n")
    status = 130

sys.exit(status)
