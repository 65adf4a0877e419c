"""``python -m ft_sitl``: the ft-sitl command line."""

import sys

from ft_sitl.cli import main

sys.exit(main())
