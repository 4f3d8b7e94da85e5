"""Loaded into schemathesis by tests/e2e/schemathesis.sh (SCHEMATHESIS_HOOKS).

A work-around for a bug of CPython 3.11, not of the server: `ast.parse` run
deep in a recursion can fail with "SystemError: AST constructor recursion
depth mismatch". Hypothesis parses a module's source to describe a lambda
the first time it meets one, and schemathesis' coverage phase meets its
filter lambdas deep in its walk of nested schemas. Which operation gets
there first depends on the order the two workers take them, so the run
failed now and then with a "Runtime Error" on an operation whose requests
were never sent (GET /api/alarms/history and /api/alarms/metrics).

Here such a parse is done again on a fresh thread, whose stack is shallow.
Any other error, and any SystemError with another message, is raised as it
was.
"""

import ast
import threading

_parse = ast.parse


def _parse_on_fresh_stack(*args, **kwargs):
    try:
        return _parse(*args, **kwargs)
    except SystemError as e:
        if "recursion depth mismatch" not in str(e):
            raise
    out = {}

    def work():
        try:
            out["tree"] = _parse(*args, **kwargs)
        except BaseException as e:  # handed back to the caller's thread
            out["error"] = e

    t = threading.Thread(target=work, name="ast-parse")
    t.start()
    t.join()
    if "error" in out:
        raise out["error"]
    return out["tree"]


ast.parse = _parse_on_fresh_stack
