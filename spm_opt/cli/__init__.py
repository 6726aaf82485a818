"""The ``spm-opt`` command line, thin over the library: its parser, its commands and the run.

:mod:`~spm_opt.cli.parser` builds the argument parser, :mod:`~spm_opt.cli.commands` holds
a handler a command, and :func:`main` (:mod:`~spm_opt.cli.run`) runs one.

A user's mistake prints one line, ``spm-opt: error: ...``, and exits with status 2; so
does a missing optional package, naming the extra that installs it. The library's
warnings reach stderr as ``spm-opt: warning: ...``; ``-v`` adds its info lines, ``-vv``
its debug lines. :data:`~spm_opt.cli.parser.EXIT_STATUSES` lists what each exit status
means.
"""

from spm_opt.cli.run import main

__all__ = ["main"]
