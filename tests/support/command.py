"""The implc command run in a fresh process, as a user runs it."""


import subprocess
import sys


def run(*argv):
    """(exit status, stdout, stderr) of the command in a fresh process, as a user runs it."""
    proc = subprocess.run([sys.executable, "-m", "implc", *argv], capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr
