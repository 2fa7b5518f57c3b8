"""The command line's stderr filter (tolsynth.cli.interrupts.QuietCasadiInterrupt): CasADi's
interrupt line dropped, everything else forwarded, and the filter done when its block ends even
while a process started inside the block (a sweep's forkserver) still holds the pipe open."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from tolsynth.cli.interrupts import QuietCasadiInterrupt


def test_filter_forwards_drops_and_ends_while_a_child_holds_the_pipe(capfd):
    child = None
    try:
        with QuietCasadiInterrupt() as q:
            child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])  # inherits fd 2
            os.write(2, b"kept line\n")
            os.write(2, b'CasADi - 2026 WARNING("KeyboardInterruptException") [.../x.cpp:1]\n')
            os.write(2, b"another\n")
            time.sleep(0.2)
            thread = q.thread
        assert child.poll() is None  # still running, still holding the pipe's write end
        assert not thread.is_alive()  # the filter did not wait for it
    finally:
        if child is not None:
            child.kill()
            child.wait()
    err = capfd.readouterr().err
    assert err == "kept line\nanother\n", err
