"""The command line, one module per subcommand: each has ``add(commands, prog)``, which declares the
subcommand and its options, and ``run(args)``; the options several commands share are in
:mod:`.options`. :mod:`pipeline.__main__` assembles them."""

from . import ablate, batch, bench, evaluate, export, hands, objects, plan

COMMANDS = (plan, batch, bench, hands, objects, ablate, export, evaluate)
