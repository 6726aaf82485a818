"""``python -m spm_opt.cli ARGS``, the same as ``spm-opt ARGS``."""

import sys

from spm_opt.cli.run import main

if __name__ == "__main__":
    sys.exit(main())
