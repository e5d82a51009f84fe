"""``python -m planner.service serve|keys ...``: deprecated, use ``planner serve`` or
``python -m planner.frontends.service``.
"""

import importlib
import sys

if __name__ == "__main__":
    sys.exit(importlib.import_module("planner.frontends.service.cli").main())
