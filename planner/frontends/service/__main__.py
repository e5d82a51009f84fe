"""``python -m planner.frontends.service serve|keys ...``."""

import sys

from planner.frontends.service.cli import main

if __name__ == "__main__":
    sys.exit(main())
