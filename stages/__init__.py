"""One thin module per DVC stage: read params and inputs, call ``pipeline``, write outputs.

Under ``make run`` a stage command hands itself to the warm stage server
(:mod:`pipeline.stage_server`) when one is named in the environment, before the stage module
imports anything; otherwise it runs here.
"""

import os
import sys

if os.environ.get("MEDIAL_GRASP_STAGE_SERVER") and sys.argv[:1] == ["-m"] and sys.orig_argv[1:2] == ["-m"]:
    # ``python -m stages.<name> ARGS``, this package imported on the way to the module
    from pipeline.stage_server import delegate

    delegate(sys.orig_argv[2], sys.argv[1:])
