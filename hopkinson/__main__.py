"""`python -m hopkinson …` is the `hopkinson` command."""

import sys

from hopkinson.rig.cli.main import main

sys.exit(main())
