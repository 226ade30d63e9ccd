"""``python -S bench/peak_rss.py OUT CMD [ARG ...]``: run CMD, write its peak resident set to OUT.

OUT receives one line, the peak in bytes: ``ru_maxrss`` of ``os.wait4`` on CMD, i.e. the largest
resident set of CMD and of every descendant it waited for (the same number ``/usr/bin/time -v``
prints). The exit status is CMD's (128 + the signal if a signal ended it).

Why a process of its own: Linux keeps a process's ``ru_maxrss`` across ``exec``, and a forked child
starts from its parent's high-water mark, so ``os.wait4`` on a command forked straight from the
bench reports at least the bench's own resident set (measured: a trivial ``python -c pass`` read
329 MB when forked from a process holding 300 MB). This script is small (no imports beyond ``os``
and ``sys``; run it with ``-S``), so the command it forks starts from about 10 MB.
Standard input, output and error are inherited.
"""

import os
import sys


def main(argv) -> int:
    if len(argv) < 2:
        sys.stderr.write("usage: python -S bench/peak_rss.py OUT CMD [ARG ...]\n")
        return 2
    out, cmd = argv[0], argv[1:]
    pid = os.fork()
    if pid == 0:  # the command, in a process forked from this small one
        try:
            os.execvp(cmd[0], cmd)
        finally:
            os._exit(127)
    _, status, usage = os.wait4(pid, 0)
    with open(out, "w") as fh:
        fh.write(f"{int(usage.ru_maxrss) * 1024}\n")
    code = os.waitstatus_to_exitcode(status)
    return 128 - code if code < 0 else code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
