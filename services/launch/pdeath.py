"""Run a command that dies with the process that started it: `python pdeath.py PARENT SIG CMD...`
arms Linux's PR_SET_PDEATHSIG (the signal SIG when PARENT dies, even by SIGKILL), checks that
PARENT is still its parent (it may have died before the signal was armed), and execs CMD in its
own process: the armed signal survives the exec. Run as a script, not a module, so that it
imports nothing of ours: a `preexec_fn` would do the same in the forked child, but Python calls
that unsafe once the parent has threads (Ray's, the supervisor's)."""

import ctypes
import os
import sys

PR_SET_PDEATHSIG = 1


def main(argv: list[str]) -> None:
    parent, sig, command = int(argv[0]), int(argv[1]), argv[2:]
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, sig, 0, 0, 0)
    if os.getppid() != parent:  # the launcher died before the signal was armed
        sys.exit(f"pdeath: the parent process {parent} is gone; not starting {command[0]}")
    os.execvp(command[0], command)


if __name__ == "__main__":
    main(sys.argv[1:])
