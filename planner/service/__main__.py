"""``python -m planner.service serve|keys ...``."""

import sys

from planner.service.cli import main

if __name__ == "__main__":
    sys.exit(main())
