"""One thin module per DVC stage: read params and inputs, call ``pipeline``, write outputs.

A stage command, ``python -m stages.<name> ARGS``, runs its module from here, before the module
imports anything: under ``make run`` it hands itself to the warm stage server
(:mod:`pipeline.stage_server`) named in the environment; otherwise, or when that server does not
take it, it runs in this process, which then ends without the interpreter's teardown
(:func:`pipeline.stage_server.run_stage`), as the server's children do.
"""

import sys

if sys.argv[:1] == ["-m"] and sys.orig_argv[1:2] == ["-m"] and sys.orig_argv[2].startswith("stages."):
    # ``python -m stages.<name> ARGS``, this package imported on the way to the module
    from pipeline.stage_server import delegate, run_stage

    # out of the modules a stage's log names as those it used (it runs them), as in the server's
    # children, which run it as ``__main__``
    del sys.modules["pipeline.stage_server"]
    delegate(sys.orig_argv[2], sys.argv[1:])
    run_stage(sys.orig_argv[2], sys.argv[1:])
