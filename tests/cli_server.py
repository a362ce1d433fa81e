"""Runs ``dtd`` commands for the tests, each in a process of its own, without each importing
torch, MuJoCo, Gymnasium-Robotics and matplotlib again.

The server imports what every command loads, then reads one request per line on stdin (JSON:
the arguments, the working directory, the environment, files for stdout and stderr). It forks
for each; the fork runs the command exactly as ``python -m dtd ARGS`` would (``dtd.__main__``
as the main module, stdin empty, stdout and stderr to the files) and exits as that process
would, after running its exit handlers. The server answers with the fork's pid, then with its
exit status (negative: the signal that ended it). Started by :func:`tests.helpers.dtd`, one
per test process; it ends when its stdin closes.

The server itself never runs a torch operation or starts a thread of its own, so that every
fork starts as a fresh interpreter would: no OpenMP pool, no locks held.
"""

from __future__ import annotations

import atexit
import json
import os
import runpy
import sys
import threading
import traceback


def preload() -> None:
    """Import what a training, evaluating, drawing or explaining command imports, through dtd's
    own modules (so that their warning filters apply as they do for the command)."""
    import torch._dynamo  # noqa: F401  (what the first torch optimiser imports)

    import dtd.cli
    import dtd.envs.make
    import dtd.training.lifecycle  # noqa: F401
    from dtd.figures import pyplot

    pyplot()  # matplotlib, for the commands that draw


def run_command(request: dict, replies: int) -> None:
    """In the fork: run ``python -m dtd`` with the request's arguments; never returns.
    ``replies``: the server's answering pipe, which the command does not keep."""
    code: object = 1
    try:
        os.close(replies)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        nothing = os.open(os.devnull, os.O_RDONLY)
        os.dup2(nothing, 0)
        os.close(nothing)
        for fd, path in ((1, request["stdout"]), (2, request["stderr"])):
            file = os.open(path, os.O_WRONLY | os.O_TRUNC)
            os.dup2(file, fd)
            os.close(file)
        sys.stdin = open(0, closefd=False)  # noqa: SIM115 (the process's own stdin)
        sys.argv = [sys.executable, *request["args"]]
        code = 0
        runpy.run_module("dtd", run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        code = exc.code
    except BaseException:
        traceback.print_exc()
        code = 1
    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    try:
        threading._shutdown()  # type: ignore[attr-defined]  (what the interpreter does at exit)
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)


def serve() -> None:
    preload()
    replies = os.fdopen(os.dup(1), "w")
    for line in sys.stdin:
        request = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            run_command(request, replies.fileno())
        replies.write(f"{pid}\n")
        replies.flush()
        _, status = os.waitpid(pid, 0)
        replies.write(f"{os.waitstatus_to_exitcode(status)}\n")
        replies.flush()


if __name__ == "__main__":
    serve()
