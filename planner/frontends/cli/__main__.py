"""``python -m planner.frontends.cli ...``: the ``planner`` command."""

import sys

from planner.frontends.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
